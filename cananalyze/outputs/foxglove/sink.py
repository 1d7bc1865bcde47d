"""`live --foxglove [HOST:PORT]`: the live decode served by foxglove-sdk's WebSocket server.

The topics, schemas and JSON documents are `export --mcap`'s (`mcap.stream.batch_messages`:
raw frames, per-PDO signals, NMT states, events and findings as foxglove.Log), so a
layout made on a recording works on the live bus and back. A channel is advertised
when its topic first appears; messages are sent only on channels a client subscribed
to (`has_sinks`), so a server nobody watches costs the JSON building alone.
Binds to loopback unless the user names another address.

Clients: foxglove-sdk's server accepts only the WebSocket subprotocol
"foxglove.sdk.v1" (fixed in its Rust handshake, no option in the Python API through
0.30); a client offering only the protocol's older name "foxglove.websocket.v1"
(Lichtblick before its 2025-12 releases, foxglove_bridge-era clients) gets HTTP 400.
The messages are the same under both names; `ACCEPTED_SUBPROTOCOLS` says what this
server takes, and the announce line and docs/live.md tell the user.

One call per message (foxglove-sdk has no batch call; the WebSocket protocol sends one
message per data frame), made on the SDK's compiled channel (`Channel.base.log`): the
Python wrapper's checks cost three times the send itself (1.2 of 1.6 µs per frame).
Payloads are built only for topics a client subscribed to (`batch_messages`' `want`):
frames, the bulk of the traffic, cost nothing until someone watches them.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from cananalyze.core.errors import UsageError
from cananalyze.core.extras import need
from cananalyze.decode.events.build import EventState, batch_events_of
from cananalyze.decode.events.columns import NO_ROW
from cananalyze.outputs.mcap.stream import batch_messages
from cananalyze.pipeline.sink import Sink

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
# messages queued per client before the server drops the oldest (the SDK's default, 1024,
# is 30 ms of a saturated bus: a client that pauses a moment would lose frames); ~10 MB
BACKLOG = 1 << 16
# what a client must offer in Sec-WebSocket-Protocol (tests/outputs/test_foxglove_clients.py
# checks the installed SDK against it); the old name alone is refused with HTTP 400
ACCEPTED_SUBPROTOCOLS = ("foxglove.sdk.v1",)
REFUSED_SUBPROTOCOLS = ("foxglove.websocket.v1",)
# live only (not in export --mcap, where the file's end says it): the last message a
# stopping server sends; it follows every other message in a client's queue
END_TOPIC = "/cananalyze/end"
# seconds a stopping server waits for subscribed clients to leave (a client that leaves
# on END_TOPIC's message goes at once, one that does not, such as Foxglove, costs this)
LINGER = 2.0


def parse_address(text: str | None) -> tuple[str, int]:
    """'HOST:PORT', 'HOST', ':PORT' or 'PORT' -> (host, port); loopback and 8765 by default."""
    if not text:
        return DEFAULT_HOST, DEFAULT_PORT
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = (text, "") if not text.isdigit() else ("", text)
    host = host.strip("[]") or DEFAULT_HOST
    try:
        number = int(port) if port else DEFAULT_PORT
    except ValueError:
        raise UsageError(f"--foxglove takes HOST:PORT (got {text!r})") from None
    if not 0 <= number <= 65535:
        raise UsageError(f"--foxglove port must be 0..65535 (got {number})")
    return host, number


class FoxgloveSink(Sink):
    """Serves each decoded batch's messages to the connected Foxglove clients."""

    needs_events = True

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, announce=None):
        # foxglove-sdk is the foxglove extra: missing, the sink is not made (before any
        # bus is opened) and the user reads which extra to install
        self._foxglove = need("foxglove", "live --foxglove", "foxglove")
        self.host = host
        self.port = port
        self.announce = announce if announce is not None else sys.stderr
        self.server = None
        self.context = None
        self._channels: dict[str, object] = {}  # topic -> foxglove.Channel
        self._event_state = EventState()
        self._offset = 0
        self._buses = False  # several buses seen: decoded topics per bus (as export --mcap)
        self._file = ""
        self._last_ns = 0  # the last frame's time: the end message's log time
        self.sent = 0  # messages handed to the server (for subscribed channels)
        self.served = 0  # batches served

    def open(self, run) -> None:
        super().open(run)
        foxglove = self._foxglove
        # foxglove.Log's file, as export --mcap names it (a live source has no file)
        self._file = Path(str(getattr(run.source, "path", "") or "")).name
        self.context = foxglove.Context()
        try:
            self.server = foxglove.start_server(
                name="cananalyze",
                host=self.host,
                port=self.port,
                context=self.context,
                message_backlog_size=BACKLOG,
            )
        except Exception as exc:  # noqa: BLE001 - the SDK raises its own error types
            raise UsageError(f"--foxglove {self.host}:{self.port}: cannot listen: {exc}") from None
        self.port = self.server.port
        # the events' and signals' JSON columns are built in pyarrow, whose first numpy
        # array imports pandas: done now, not in the first batch a client watches (1-2 s
        # the live reader would wait, profiled under load)
        from cananalyze.core.columns.json_text import number_text

        number_text(np.zeros(1, np.int64))
        number_text(np.zeros(1, np.float64))
        # the topics every bus has, advertised before the first frame: a client can
        # subscribe and miss nothing
        from cananalyze.formats.mcap_frames import FRAME_SCHEMA, FRAMES_TOPIC
        from cananalyze.outputs.mcap.topics import EVENTS_TOPIC, LOG_SCHEMA

        self._channel(("frames",), FRAMES_TOPIC, FRAME_SCHEMA)
        self._channel(("events",), EVENTS_TOPIC, LOG_SCHEMA)
        self._channel(("end",), END_TOPIC, LOG_SCHEMA)
        if self.announce:
            print(
                f"foxglove: serving ws://{self.host}:{self.port} to clients that speak "
                f"{', '.join(ACCEPTED_SUBPROTOCOLS)} (Foxglove; Lichtblick from its 2025-12 "
                f"releases); {', '.join(REFUSED_SUBPROTOCOLS)}-only clients are refused",
                file=self.announce,
                flush=True,
            )

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def _channel(self, key: tuple, topic: str, schema: dict):
        """One channel per topic (foxglove-sdk keeps one per topic; a PDO remapped during
        the log keeps its first schema, its documents carry their own field names)."""
        ch = self._channels.get(topic)
        if ch is None:
            foxglove = self._foxglove
            sch = foxglove.Schema(
                name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
            )
            ch = self._channels[topic] = foxglove.Channel(
                topic, schema=sch, message_encoding="json", context=self.context
            )
        return ch

    def write(self, batch) -> None:
        fb = batch.frames
        off = self._offset
        events, states = batch_events_of(batch, off, self._event_state)
        lines = np.zeros(len(events), np.int64)
        if len(events) and len(fb):
            local = events.row - off
            ok = (events.row != NO_ROW) & (local >= 0) & (local < len(fb))
            lines[ok] = fb.line[local[ok]]
        self._offset += len(fb)
        if len(fb):
            self._last_ns = int(round(float(fb.t[-1]) * 1e9))
        self._buses = self._buses or len(fb.channels) > 1
        blocks = [(b.node, b.pdo, b.cob_id, b.rows, b.columns, b.units) for b in batch.signals]
        for key, topic, schema, ns, payload in batch_messages(
            fb,
            batch.service,
            batch.node,
            blocks,
            states,
            events,
            lines,
            self._file,
            batch.drive,
            want=self._watched,
            buses=self._buses,
            offset=off,
        ):
            ch = self._channel(key, topic, schema)  # advertised even when nobody watches
            if payload is None or not ch.has_sinks():
                continue
            blob = payload.data.tobytes()
            cuts = payload.offsets.tolist()
            log = ch.base.log
            for t, a, b in zip(ns.tolist(), cuts, cuts[1:]):  # noqa: B905 - cuts is one longer
                log(blob[a:b], t)
            self.sent += len(ns)
        self.served += 1

    def _watched(self, topic: str) -> bool:
        """A client subscribed to the topic's channel (a topic not yet advertised has none)."""
        ch = self._channels.get(topic)
        return ch is not None and ch.has_sinks()

    def close(self) -> None:
        self._stop()

    def abort(self) -> None:
        self._stop()

    def _stop(self) -> None:
        """Hand the clients the last messages, then stop the server.

        foxglove-sdk has no flush: stopping sends each client Close without draining its
        queue (`connected_client/poller.rs`), so messages logged just before, such as the
        longest burst that only the end of a run knows, were lost. One queue per client
        is first in first out, so a client that has END_TOPIC's message has every message
        before it; the server waits (at most LINGER s) until its subscribed clients left.
        """
        if self.server is None:
            return
        end = self._channels.get(END_TOPIC)
        if end is not None and end.has_sinks():
            now = self._last_ns or time.time_ns()
            doc = {
                "timestamp": {"sec": now // 1_000_000_000, "nsec": now % 1_000_000_000},
                "level": 2,
                "message": f"live decode ended: {self.sent} messages served",
                "name": "cananalyze",
                "file": self._file,
                "line": 0,
            }
            end.base.log(json.dumps(doc).encode(), now)
            self.sent += 1
        deadline = time.monotonic() + LINGER
        while time.monotonic() < deadline and any(c.has_sinks() for c in self._channels.values()):
            time.sleep(0.01)
        for ch in self._channels.values():
            ch.close()
        self.server.stop()
        self.server = None
