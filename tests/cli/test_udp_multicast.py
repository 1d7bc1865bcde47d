"""`cananalyze simulate` and `cananalyze live` in two processes on python-can's udp_multicast,
the no-hardware path of docs/live.md: every frame the simulator sends arrives once.

Only the interface-local group ff11::cafe is used: Linux loops it back to this host and
never sends it on a wire, so these tests reach no other address (python-can's default
group, ff15:..., is site-local and goes out on the LAN). Each test takes its own port."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading

import can
import pytest
from conftest import ROOT

from cananalyze.cli.main import main

GROUP = "ff11::cafe"  # interface-local: loopback only
PROBE = 0x7E5  # the test's own marker frames (LSS master requests), left out of every count


def _free_port() -> int:
    with socket.socket(socket.AF_INET6, socket.SOCK_DGRAM) as s:
        s.bind(("::", 0))
        return s.getsockname()[1]


def _bus(port: int) -> can.BusABC:
    return can.Bus(interface="udp_multicast", channel=GROUP, port=port)


def _multicast_or_skip(port: int) -> None:
    """Skip, with what was measured, where IPv6 multicast does not loop back on this host."""
    try:
        a, b = _bus(port), _bus(port)
    except (can.CanError, OSError) as exc:
        pytest.skip(f"udp_multicast on {GROUP}: cannot open a bus here: {exc}")
    try:
        a.send(can.Message(arbitration_id=PROBE, data=b"\x4c" + bytes(7), is_extended_id=False))
        got = b.recv(timeout=5.0)
    finally:
        a.shutdown()
        b.shutdown()
    if got is None:
        pytest.skip(f"udp_multicast on {GROUP}: a frame sent was not received in 5 s here")


class _Reader:
    """Every frame of the group, read on a thread so the socket's buffer never fills."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus, self.frames, self._stop = bus, [], threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(timeout=0.1)
            if msg is not None:
                self.frames.append(msg)

    def close(self) -> list[can.Message]:
        self._stop.set()
        self._thread.join()
        while (msg := self.bus.recv(timeout=0.5)) is not None:  # already queued
            self.frames.append(msg)
        return [m for m in self.frames if m.arbitration_id != PROBE]


def _probe(bus: can.BusABC, seq: int) -> None:
    bus.send(can.Message(arbitration_id=PROBE, data=bytes([0x4C, seq, 0, 0, 0, 0, 0, 0])))


def _wait_for_line(lines: list[str], text: str, proc: subprocess.Popen, bus, seq: int) -> None:
    """Probe until live prints the probe: it reads the group from then on."""
    for _ in range(300):  # up to 60 s: a loaded machine may take long to start Python
        _probe(bus, seq)
        if any(text in line for line in lines):
            return
        if proc.poll() is not None:
            pytest.fail(f"live ended early: {proc.stderr.read()}")
        threading.Event().wait(0.2)
    proc.kill()
    pytest.fail(f"live never printed its probe {text!r}")


def _key(m: can.Message) -> tuple:
    return (m.arbitration_id, m.is_remote_frame, b"" if m.is_remote_frame else bytes(m.data))


def _cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "cananalyze", *args]


@pytest.mark.slow
def test_simulate_to_live_across_processes_each_frame_once(tmp_path):
    port = _free_port()
    _multicast_or_skip(port)
    env = dict(os.environ, PYTHONPATH=str(ROOT), TERM="dumb")
    bus = ["-i", "udp_multicast", "-c", GROUP, "--bus-option", f"port={port}"]
    recording = tmp_path / "live.log"
    live = subprocess.Popen(
        _cli("live", *bus, "--plain", "--record", str(recording)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
    )
    lines: list[str] = []
    pump = threading.Thread(target=lambda: lines.extend(live.stdout), daemon=True)
    pump.start()
    reader = _Reader(_bus(port))
    try:
        _wait_for_line(lines, f"{PROBE:03X}", live, reader.bus, 0x00)
        sim = subprocess.run(
            _cli("simulate", *bus, "--scenario", "commissioning", "--duration", "4"),
            capture_output=True,
            text=True,
            env=env,
            cwd=ROOT,
            timeout=120,
        )
        assert sim.returncode == 0, sim.stderr
        # everything the simulator sent is queued before this: once live prints it, live has
        # read them all
        _wait_for_line(lines, "4C EE", live, reader.bus, 0xEE)
        live.send_signal(signal.SIGINT)  #: the recording is finalised
        live.wait(timeout=60)
    finally:
        if live.poll() is None:
            live.kill()
        seen = reader.close()
        reader.bus.shutdown()
    assert live.returncode == 0, live.stderr.read()

    # the simulator's guarding: each request of the master answered once, toggling
    guard = [m for m in seen if m.arbitration_id == 0x707]
    first = next(i for i, m in enumerate(guard) if m.is_remote_frame)
    kinds = [m.is_remote_frame for m in guard[first:]]
    assert kinds.count(True) >= 10
    assert all(a != b for a, b in zip(kinds, kinds[1:], strict=False)), "a request answered twice"
    toggles = [m.data[0] & 0x80 for m in guard[first:] if not m.is_remote_frame]
    assert all(a != b for a, b in zip(toggles, toggles[1:], strict=False))
    # TPDO2 of node 5, remapped to every 5th SYNC: five SYNCs between any two of them
    syncs, between = 0, []
    for m in seen:
        if m.arbitration_id == 0x080:
            syncs += 1
        elif m.arbitration_id == 0x285:
            between.append(syncs)
            syncs = 0
    assert len(between) >= 4 and set(between[1:]) == {5}, between
    # each SDO request answered once
    for node in (3, 5, 6, 7):
        asked = sum(m.arbitration_id == 0x600 + node for m in seen)
        assert asked and sum(m.arbitration_id == 0x580 + node for m in seen) == asked

    # live recorded exactly the frames on the group, once each, in order
    recorded = [m for m in can.LogReader(str(recording)) if m.arbitration_id != PROBE]
    assert [_key(m) for m in recorded] == [_key(m) for m in seen]

    # and `check` of that recording finds nothing wrong with the guarding (doubled replies
    # were 75 toggle-bit findings in 8 s) nor with SYNC counting (TPDOs every 2.5th SYNC).
    # Only the master's schedule is timing, which a loaded machine may stretch: not judged.
    clean = tmp_path / "clean.log"
    with can.Logger(str(clean)) as log:
        for m in recorded:
            log(m)
    findings = tmp_path / "findings.json"
    assert main(["check", str(clean), "--json", str(findings)]) in (0, 1)
    schedule = ("guard request period", "life time exceeded")
    wrong = [
        (f["rule"], f["message"])
        for f in json.loads(findings.read_text())
        if f["rule"] in ("guarding", "pdo_sync") and not f["message"].startswith(schedule)
    ]
    assert wrong == []
