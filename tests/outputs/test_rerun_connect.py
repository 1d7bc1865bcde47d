"""`decode --connect ADDR` streams to a running rerun server, read back from what it saved.

The server is the `rerun` binary of the rerun-sdk wheel in `--save` mode, bound to
127.0.0.1 on a free port: it accepts SDK connections like a viewer does and writes
everything it receives to an .rrd, which is compared with `export --rrd`'s file read
with rerun's own reader.
"""

from __future__ import annotations

import os
import socket
import subprocess
import time
from pathlib import Path

import pytest
from conftest import SAMPLES

from cananalyze.cli.main import main

DEMO = SAMPLES / "demo.log"
DEVICES = ["--device", "3=mcb560", "--device", "5=dat7014"]


def _rerun_binary() -> Path:
    try:
        import rerun_cli
    except ImportError:
        pytest.skip("rerun-sdk without its rerun binary")
    exe = Path(rerun_cli.__file__).parent / "rerun"
    if not exe.is_file():
        pytest.skip("rerun-sdk without its rerun binary")
    return exe


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(port: int, proc: subprocess.Popen, timeout: float = 30) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            pytest.fail(f"rerun server exited with {proc.returncode}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.2)
    pytest.fail("rerun server did not listen on 127.0.0.1")


def _rows(path: Path) -> dict[str, list]:
    """Rows per entity (time and components; row ids differ between recordings)."""
    from rerun.chunk import RrdReader

    rows: dict[str, list] = {}
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            batch = chunk.to_record_batch().to_pylist()
            rows.setdefault(chunk.entity_path, []).extend(
                {k: v for k, v in r.items() if k != "rerun.controls.RowId"} for r in batch
            )
    return rows


@pytest.mark.filterwarnings("ignore:RRD file has no footer")
def test_connect_streams_the_same_recording_as_the_rrd_export(tmp_path):
    exe = _rerun_binary()
    port = _free_port()
    received = tmp_path / "received.rrd"
    env = dict(os.environ, XDG_CONFIG_HOME=str(tmp_path / "config"))  # no user settings
    with open(tmp_path / "server.log", "wb") as log:
        server = subprocess.Popen(
            [exe, "--bind", "127.0.0.1", "--port", str(port), "--save", str(received)],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
        )
    try:
        _wait_listening(port, server)
        assert main(["decode", str(DEMO), *DEVICES, "--connect", f"127.0.0.1:{port}"]) == 0
        assert (
            main(
                [
                    "export",
                    str(DEMO),
                    "--no-check",  # decode runs no rules: no findings in either recording
                    *DEVICES,
                    "--rrd",
                    str(tmp_path / "x.rrd"),
                    "-q",
                ]
            )
            == 0
        )
        expected = _rows(tmp_path / "x.rrd")
        end = time.monotonic() + 30
        got: dict[str, list] = {}
        while time.monotonic() < end:  # the server writes as it receives
            if received.exists():
                try:
                    got = _rows(received)
                except Exception:  # a chunk half written: read again
                    got = {}
                if {k: len(v) for k, v in got.items()} == {k: len(v) for k, v in expected.items()}:
                    break
            time.sleep(0.3)
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
    assert set(got) == set(expected) and "/events" in got and "/node/5/nmt" in got
    for path, rows in expected.items():
        assert got[path] == rows, path
