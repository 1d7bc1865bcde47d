"""Boot stories (CiA 302-2) from python-canopen: its SDO client and NMT master booting a
LocalNode that serves ros2_canopen's CiA 402 EDS, healthy and with one fault each: an
identity that differs from the declared device, a configuration write the node aborts,
no NMT start; and, by hand, a heartbeat producer that never beats.
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
from pathlib import Path

import can
import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

import cananalyze
from cananalyze.decode.boot import NO_START_S
from tests.conftest import real_file
from tests.helpers.virtual_bus import drain, patient_client, unique_channel

SLAVE_EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"


def _record(path, *, write_read_only=False, start=True) -> None:
    """A master's CiA 302-2 walk: boot-up, device type and identity read, heartbeat and
    mode written, [a write the node refuses: the master stops], [NMT start]."""
    logging.getLogger("canopen").setLevel(logging.ERROR)
    channel = unique_channel("boot")
    recorder = can.Bus(interface="virtual", channel=channel)
    slave_net, master_net = canopen.Network(), canopen.Network()
    slave_net.connect(interface="virtual", channel=channel)
    master_net.connect(interface="virtual", channel=channel)
    drive = canopen.LocalNode(5, str(real_file(SLAVE_EDS)))
    try:
        slave_net.add_node(drive)
        drive.sdo[0x1018][2].raw = 0x2  # the EDS has no default: the node answers these
        drive.sdo[0x1018][3].raw = 0x10001
        master = patient_client(5)
        master_net.add_node(master)
        drive.nmt.send_command(0x81)  # boot-up
        drive.nmt.send_command(0x80)
        # a heartbeat producer from here (set before, python-canopen beats 0x00, a second
        # boot-up on the wire, while it is still initialising)
        drive.sdo[0x1017].raw = 50
        drive.nmt.start_heartbeat(50)
        for index, sub in ((0x1000, 0), (0x1018, 1), (0x1018, 2), (0x1018, 3)):
            master.sdo.upload(index, sub)
        master.sdo.download(0x6060, 0, b"\x01")
        stop = False
        if write_read_only:
            try:
                master.sdo.download(0x1000, 0, b"\0\0\0\0")  # read-only: aborted
            except SdoAbortedError:
                stop = True  # CiA 302-2: configuration failed, the node is not started
        frames = []
        if start and not stop:
            master.nmt.state = "OPERATIONAL"
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:  # until the node reports operational
                m = recorder.recv(timeout=0.1)
                if m is not None:
                    frames.append(m)
                    if m.arbitration_id == 0x705 and m.data[:1] == b"\x05":
                        break
        else:
            time.sleep(NO_START_S + 0.2)  # heartbeats, pre-operational, long enough to judge
        drive.nmt.stop_heartbeat()  # else the recorder never falls quiet
        frames += drain(recorder)
    finally:
        drive.nmt.stop_heartbeat()
        slave_net.disconnect()
        master_net.disconnect()
        recorder.shutdown()
    with can.CanutilsLogWriter(str(path), channel="vcan0") as w:
        for m in frames:
            w.on_message_received(m)


def _boot(log, *args) -> list[dict]:
    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "boot", str(log), "--format", "jsonl", *args],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    return [json.loads(x) for x in run.stdout.splitlines()]


def test_a_healthy_boot_is_operational(tmp_path):
    log = tmp_path / "ok.log"
    _record(log)
    [story] = _boot(log)
    assert (story["node"], story["life"], story["result"], story["status"]) == (
        5,
        1,
        "operational",
        None,
    )
    steps = story["steps"].split("; ")
    assert steps[0] == "boot-up: seen" and steps[-2:] == [
        "NMT start: sent",
        "operational: reported",
    ]
    assert "identity: device type: 0x00060192" in steps and "error control: heartbeat" in steps
    f = cananalyze.load(log).findings
    assert not (f["rule"] == "boot").any()


def test_an_identity_that_differs_from_the_declared_device(tmp_path):
    """Declared a DAT 7014 (device type 0x00040191): the node says 0x00060192, and the
    master stops there: error C (the first failed step of CiA 302-2's order)."""
    log = tmp_path / "identity.log"
    _record(log, start=False)
    [story] = _boot(log, "--device", "5=dat7014")
    assert (story["result"], story["stopped_at"], story["status"]) == ("stopped", "identity", "C")
    assert "device type 0x60192, expected 0x40191" in story["verdict"]
    f = cananalyze.load(log, device={5: "dat7014"}).findings
    boot = f[f["rule"] == "boot"]
    assert len(boot) == 1 and boot["severity"].iloc[0] == "error"
    assert "CiA 302-2 error C" in boot["message"].iloc[0]


def test_an_aborted_configuration_write(tmp_path):
    log = tmp_path / "config.log"
    _record(log, write_read_only=True)
    [story] = _boot(log)
    assert (story["result"], story["stopped_at"], story["status"]) == (
        "stopped",
        "configuration",
        "J",
    )
    assert "0x1000:00 aborted 0x06010002" in story["verdict"]


def test_no_nmt_start_is_told_not_failed(tmp_path):
    log = tmp_path / "nostart.log"
    _record(log, start=False)
    [story] = _boot(log)
    assert (story["result"], story["stopped_at"], story["status"]) == ("stopped", "NMT start", None)
    f = cananalyze.load(log).findings
    boot = f[f["rule"] == "boot"]
    assert boot["severity"].tolist() == ["info"]  # told, not a violation


def test_a_heartbeat_producer_that_never_beats(tmp_path):
    """0x1017 written as 100 ms, the node started, then 2 s of SYNC and no heartbeat."""
    lines = ["(0.000000) vcan0 705#00"]
    lines += ["(0.010000) vcan0 605#2B17100064000000", "(0.011000) vcan0 585#6017100000000000"]
    lines += ["(0.020000) vcan0 000#0105"]
    lines += [f"({0.1 + k * 0.1:.6f}) vcan0 080#" for k in range(20)]
    log = tmp_path / "k.log"
    log.write_text("\n".join(lines) + "\n")
    [story] = _boot(log)
    assert (story["status"], story["stopped_at"]) == ("K", "error control")
    assert "no heartbeat, 0x1017 is 100 ms" in story["verdict"]


def test_text_tells_the_steps(tmp_path):
    log = tmp_path / "config.log"
    _record(log, write_read_only=True)
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "boot", str(log)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.splitlines()
    assert out[0].startswith("node 5, boot-up 1 at ")
    assert out[-1].startswith("  => stopped at configuration: 0x1000:00 aborted 0x06010002")
    assert out[-1].endswith("(CiA 302-2 error J: configuration download failed)")


@pytest.mark.parametrize("log", ["commissioning.log", "faults.log"])
def test_the_samples_boot(log):
    from tests.conftest import SAMPLES

    boot = cananalyze.load(SAMPLES / log, network=SAMPLES / "network.toml").boot
    assert boot["result"].tolist() == ["operational"] * 4


DOCS = Path(__file__).resolve().parents[2] / "docs" / "decoding.md"


def _docs_block(command: str) -> list[str]:
    """The lines docs/decoding.md shows for `$ <command>` (its "..." lines are cuts)."""
    text = DOCS.read_text(encoding="utf-8")
    block = text.split(f"$ {command}\n", 1)[1].split("```", 1)[0]
    return [line for line in block.splitlines() if line.strip() != "..."]


def _cananalyze(*args: str) -> list[str]:
    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, timeout=120
    )
    assert run.returncode in (0, 1), run.stderr
    return run.stdout.splitlines()


def test_the_docs_real_trace_story_is_the_output():
    """docs/decoding.md's pcan1.trc boot stories are what `boot` prints, line for line and
    in order (the docs cut lines, never change them)."""
    out = _cananalyze("boot", str(real_file("hilch__canopen-message-interpreter/pcan1.trc")))
    shown = _docs_block("cananalyze boot pcan1.trc")
    assert len(shown) > 10
    at = 0
    for line in shown:
        at = out.index(line, at) + 1  # ValueError: the docs show a line boot does not print


def test_the_docs_simulated_faults_are_the_output(tmp_path):
    """docs/decoding.md's commissioning-faults examples (identity mismatch, LSS assignment)
    are what `boot` and `decode --summary` print on the simulator's log."""
    log = tmp_path / "cf.log"
    network = str(Path(__file__).resolve().parents[2] / "samples" / "network.toml")
    _cananalyze("simulate", "--scenario", "commissioning-faults", "--to", str(log))
    for command, args in (
        ("cananalyze boot cf.log --network samples/network.toml", ("boot",)),
        (
            "cananalyze decode cf.log --network samples/network.toml --summary",
            ("decode", "--summary"),
        ),
    ):
        out = _cananalyze(*args[:1], str(log), "--network", network, *args[1:])
        shown = _docs_block(command)
        assert shown
        at = 0
        for line in shown:
            at = out.index(line, at) + 1


def test_range_rows_are_the_rows_of_those_services() -> None:
    """boot._range_rows (heartbeat..guard response and NMT by one range test, uint8 codes
    wrapping below the range) finds the rows a comparison per code finds, for every code
    and for a service column that is not uint8."""
    import numpy as np

    from cananalyze.decode.boot import _range_rows
    from cananalyze.decode.lss import _is_lss
    from cananalyze.protocol.services import Service

    svc = np.arange(256, dtype=np.uint8).repeat(3)
    codes = (Service.HEARTBEAT, Service.BOOTUP, Service.GUARD_REQUEST, Service.GUARD_RESPONSE)
    want = np.flatnonzero(np.isin(svc, (*codes, Service.NMT)))
    got = _range_rows(svc, Service.HEARTBEAT, Service.GUARD_RESPONSE, Service.NMT)
    assert got.tolist() == want.tolist()
    wide = svc.astype(np.int64)
    assert _range_rows(wide, 9, 12, 1).tolist() == want.tolist()
    lss = np.isin(svc, (Service.LSS_MASTER, Service.LSS_SLAVE))
    assert (_is_lss(svc) == lss).all() and (_is_lss(wide) == lss).all()
