"""Which Foxglove WebSocket clients `live --foxglove` takes (issue 44 item 8), on 127.0.0.1.

foxglove-sdk's server accepts the subprotocol "foxglove.sdk.v1" only; a client offering
only the older "foxglove.websocket.v1" (Lichtblick before its 2025-12 releases) is
refused with HTTP 400. The sink declares what is accepted (`ACCEPTED_SUBPROTOCOLS`) and
docs/live.md says it: this checks the installed SDK against both, so an SDK that starts
accepting the old name fails here and the docs get updated.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from cananalyze.outputs.foxglove.sink import (
    ACCEPTED_SUBPROTOCOLS,
    REFUSED_SUBPROTOCOLS,
    FoxgloveSink,
)

pytest.importorskip("foxglove")
pytest.importorskip("websockets")

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def served():
    sink = FoxgloveSink(host="127.0.0.1", port=0, announce=False)
    sink.open(SimpleNamespace(source=SimpleNamespace(path="faults.log")))
    assert sink.url.startswith("ws://127.0.0.1:")
    yield sink
    sink.abort()


def _offer(url: str, protocol: str):
    """Connect offering one subprotocol: (chosen subprotocol, first message) or the HTTP
    status the server refused with."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    try:
        with connect(url, subprotocols=[protocol], open_timeout=10) as ws:
            return ws.subprotocol, json.loads(ws.recv(timeout=10))
    except InvalidStatus as exc:
        return exc.response.status_code, None


@pytest.mark.parametrize("protocol", ACCEPTED_SUBPROTOCOLS)
def test_current_clients_connect(served, protocol):
    chosen, first = _offer(served.url, protocol)
    assert chosen == protocol
    assert first["op"] == "serverInfo" and first["name"] == "cananalyze"


@pytest.mark.parametrize("protocol", REFUSED_SUBPROTOCOLS)
def test_old_only_clients_are_refused_as_documented(served, protocol):
    status, first = _offer(served.url, protocol)
    assert status == 400 and first is None
    # still serving the others after the refusal
    assert _offer(served.url, ACCEPTED_SUBPROTOCOLS[0])[0] == ACCEPTED_SUBPROTOCOLS[0]


def test_the_docs_say_which_clients_connect():
    page = (ROOT / "docs" / "live.md").read_text()
    for name in (*ACCEPTED_SUBPROTOCOLS, *REFUSED_SUBPROTOCOLS):
        assert f"`{name}`" in page
    assert "HTTP 400" in page
