"""Issue 38 item 6: `live --record` killed in any way leaves a readable recording with
every frame it had for a second or more. A live session on python-can's udp_multicast
(the interface-local group ff11::cafe: loopback only, a port of its own) records while
this test sends frames; once python-can reads them all from the file (the once-a-second
flush), the session is killed with SIGKILL, SIGINT or SIGTERM. The recording is then read
by python-can (candump, ASC, BLF) or the mcap library: every frame, in order. INT and
TERM also finalise it (BLF header counts, MCAP summary)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

import can
import pytest
from conftest import ROOT
from test_udp_multicast import GROUP, _bus, _free_port, _multicast_or_skip

SENT = 40
MARK = 0x7E5  # the test's probes until live is listening: not counted


def _read(path) -> list[tuple]:
    """(id, data) of every frame in the recording, by an independent reader; a killed
    MCAP (no summary, maybe a cut chunk) is read record by record up to where it ends."""
    out = []
    if path.suffix == ".mcap":
        import json

        from mcap.exceptions import McapError
        from mcap.records import Message
        from mcap.stream_reader import StreamReader

        with open(path, "rb") as f:
            try:
                for rec in StreamReader(f, skip_magic=False).records:
                    if isinstance(rec, Message):
                        m = json.loads(rec.data)
                        out.append((m["can_id"], bytes.fromhex(m["data"].replace(" ", ""))))
            except (McapError, EOFError, ValueError):
                pass  # the end a kill left: what came before is kept
        return out
    try:
        for m in can.LogReader(str(path)):
            out.append((m.arbitration_id, bytes(m.data)))
    except Exception:  # noqa: BLE001 - a cut last line or container: what came before counts
        pass
    return out


@pytest.mark.slow
@pytest.mark.parametrize("how", ["KILL", "INT", "TERM"])
@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".mcap"])
def test_a_killed_recording_keeps_every_frame_of_the_last_second(suffix, how, tmp_path):
    port = _free_port()
    _multicast_or_skip(port)
    env = dict(os.environ, PYTHONPATH=str(ROOT), TERM="dumb")
    recording = tmp_path / f"rec{suffix}"
    live = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "cananalyze",
            "live",
            "-i",
            "udp_multicast",
            "-c",
            GROUP,
            "--bus-option",
            f"port={port}",
            "--plain",
            "--record",
            str(recording),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
    )
    bus = _bus(port)
    want = [(0x181 + k % 3, bytes([k, k ^ 0x5A, 1, 2])) for k in range(SENT)]
    try:
        wait = threading.Event()
        for k in range(600):  # until a probe is on the file: live listens and flushes
            bus.send(can.Message(arbitration_id=MARK, data=bytes([0x4C, k & 0xFF])))
            if recording.exists() and any(i == MARK for i, _ in _read(recording)):
                break
            if live.poll() is not None:
                pytest.fail(f"live ended early: {live.stderr.read()}")
            wait.wait(0.2)
        else:
            pytest.fail("live never recorded a probe")
        for i, data in want:
            bus.send(can.Message(arbitration_id=i, data=data, is_extended_id=False))
        for _ in range(600):  # each frame on the file within the flush's second
            if [f for f in _read(recording) if f[0] != MARK] == want:
                break
            wait.wait(0.2)
        live.send_signal(getattr(signal, f"SIG{how}"))
        live.wait(timeout=60)
    finally:
        if live.poll() is None:
            live.kill()
        bus.shutdown()
    got = [f for f in _read(recording) if f[0] != MARK]
    assert got == want, f"{len(got)} of {SENT} frames in the {how}ed recording"
    if how == "KILL":
        return
    assert live.returncode == 0, live.stderr.read()
    if suffix == ".blf":  # finalised: the header counts every object
        with can.BLFReader(str(recording)) as r:
            assert r.object_count >= SENT
    if suffix == ".mcap":
        from mcap.reader import make_reader

        with open(recording, "rb") as f:
            summary = make_reader(f).get_summary()
        assert summary is not None and summary.statistics.message_count >= SENT
