"""A CiA 402 drive's PDO words as data, and a PDO longer than the default mapping not
named by it (issue 37, item 5).

The drive is python-canopen's LocalNode on the ros2_canopen CiA 402 slave EDS. It sends
TPDO1 (statusword) and TPDO3 first with its EDS mapping (statusword + position actual,
6 bytes: CiA 402's default), then remapped to position and velocity actual (8 bytes, no
statusword). cananalyze gets `--device 5=cia402` and no EDS: it assumes the defaults.
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys

import can
import canopen

import cananalyze
from tests.conftest import real_file
from tests.helpers.virtual_bus import drain, unique_channel

SLAVE_EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"
STATUS = 0x0637  # operation enabled; voltage enabled, remote, target reached


def _record(tmp_path) -> str:
    logging.getLogger("canopen").setLevel(logging.ERROR)
    channel = unique_channel("drivefields")
    recorder = can.Bus(interface="virtual", channel=channel)
    net = canopen.Network()
    net.connect(interface="virtual", channel=channel)
    try:
        drive = canopen.LocalNode(5, str(real_file(SLAVE_EDS)))
        net.add_node(drive)
        drive.tpdo.read(from_od=True)
        t1, t3 = drive.tpdo[1], drive.tpdo[3]
        assert [(v.index, v.length) for v in t3.map] == [(0x6041, 16), (0x6064, 32)]
        t1.map[0].raw = STATUS
        t3.map[0].raw = STATUS
        t3.map[1].raw = 123456
        for _ in range(3):
            t1.transmit()
            t3.transmit()
        t3.clear()  # the drive's own mapping: no statusword in TPDO3
        t3.add_variable(0x6064)
        t3.add_variable(0x606C)
        t3.map[0].raw = -1  # FF FF FF FF: as a statusword, "fault"-like bits
        t3.map[1].raw = -1000
        for _ in range(3):
            t3.transmit()
        frames = drain(recorder)
    finally:
        net.disconnect()
        recorder.shutdown()
    path = tmp_path / "drive.log"
    path.write_text(
        "".join(
            f"({m.timestamp:.6f}) can0 {m.arbitration_id:03X}#{m.data.hex().upper()}\n"
            for m in frames
        )
    )
    return str(path)


def _jsonl(log: str, *more: str) -> list[dict]:
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", log, "--device", "5=cia402"]
        + ["--format", "jsonl", *more],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    return [r for r in map(json.loads, out.splitlines()) if r.get("kind") == "frame"]


def test_drive_words_are_data_in_jsonl(tmp_path):
    log = _record(tmp_path)
    rows = _jsonl(log)
    tpdo1 = [r for r in rows if r["can_id"] == 0x185]
    assert len(tpdo1) == 3
    for r in tpdo1:
        assert r["signals"] == {"statusword": STATUS}
        assert r["drive"] == {
            "statusword": {
                "state": "operation enabled",
                "flags": ["voltage enabled", "remote", "target reached"],
            }
        }
        assert "signal_words" not in r
    six = [r for r in rows if r["can_id"] == 0x385 and r["dlc"] == 6]
    assert len(six) == 3 and all(
        r["drive"]["statusword"]["state"] == "operation enabled" for r in six
    )
    # the text output words the same data
    text = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", log, "--device", "5=cia402"],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    assert "statusword=1591 (operation enabled; voltage enabled, remote, target reached)" in text


def test_a_pdo_longer_than_the_default_mapping_is_not_named_by_it(tmp_path):
    log = _record(tmp_path)
    rows = _jsonl(log)
    eight = [r for r in rows if r["can_id"] == 0x385 and r["dlc"] == 8]
    assert len(eight) == 3
    for r in eight:
        assert "signals" not in r and "drive" not in r
        assert r["pdo_problem"].startswith("DLC 8 longer than the 6 bytes of TPDO3's default")
    # load(): no statusword signal from those frames, no drive state from them
    cap = cananalyze.load(log, device={5: "cia402"})
    sig = cap.signals[(cap.signals.cob_id == 0x385) & (cap.signals.signal == "statusword")]
    assert len(sig) == 3 and set(sig.value) == {STATUS}
    assert set(cap.drive_states.state) == {"operation enabled"}
