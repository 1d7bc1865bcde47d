"""A master's node-ID scan is one info finding, not a timeout per absent node-ID.

The traffic is python-canopen's: `network.scanner.search()` probes node-IDs 1-127 with
SDO reads of 0x1000; two LocalNodes (2 and 5) answer. Then the master reads node 9
(absent: one unanswered read is no scan, so it stays a finding) and node 5 after that
node went silent (a node that exists: its timeout stays a finding).
"""

from __future__ import annotations

import logging
import subprocess
import sys
import time

import can
import canopen
import pytest
from canopen.sdo.exceptions import SdoCommunicationError

import cananalyze
from tests.conftest import real_file
from tests.helpers.virtual_bus import drain, unique_channel

EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"


def _record(tmp_path, limit: int = 127) -> str:
    logging.getLogger("canopen").setLevel(logging.CRITICAL)
    channel = unique_channel("scan")
    recorder = can.Bus(interface="virtual", channel=channel)
    master = canopen.Network()
    master.connect(interface="virtual", channel=channel)
    servers = {}
    for node in (2, 5):
        net = canopen.Network()
        net.connect(interface="virtual", channel=channel)
        net.add_node(canopen.LocalNode(node, str(real_file(EDS))))
        servers[node] = net
    try:
        master.scanner.search(limit)
        deadline = time.monotonic() + 5
        while set(master.scanner.nodes) != {2, 5} and time.monotonic() < deadline:
            time.sleep(0.01)  # how long the answers take (no judgement of timing rests on it)
        assert sorted(master.scanner.nodes) == [2, 5]
        # the scan's reads time out (1 s, the SDO timeout) before the master's next read
        # of node 9: a sleep only lengthens the gap, so load cannot shorten it (the gap
        # was python-can's notifier stopping below, up to its 1 s receive timeout, and a
        # quick stop made node 9's scan read "answered" by the next request instead)
        time.sleep(1.1)
        servers.pop(5).disconnect()  # node 5 goes silent
        for node in (9, 5):
            remote = canopen.RemoteNode(node, canopen.ObjectDictionary())
            master.add_node(remote)
            remote.sdo.RESPONSE_TIMEOUT = 0.05
            remote.sdo.MAX_RETRIES = 1  # one try (0 retries forever in python-canopen)
            with pytest.raises(SdoCommunicationError):
                remote.sdo.upload(0x1018, 1)
        frames = drain(recorder)
    finally:
        master.disconnect()
        for net in servers.values():
            net.disconnect()
        recorder.shutdown()
    path = tmp_path / "scan.log"
    path.write_text(
        "".join(
            f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#{m.data.hex().upper()}\n"
            for m in frames
        )
    )
    return str(path)


def _sdo(findings):
    sdo = findings[findings.rule == "sdo"]
    return sdo[sdo.severity == "info"], sdo[sdo.severity != "info"]


# python-canopen's client gives up after one try and aborts (0x05040000): those two stay
AFTER = [
    (5, "SDO upload 0x1018:01 abort: SDO protocol timed out"),
    (9, "SDO upload 0x1018:01 abort: SDO protocol timed out"),
]


NO_ANSWER = (
    "SDO upload 0x1000:00 timeout: no frame within 1 s while waiting for the initiate response"
)


def test_scan_is_one_info_finding_and_real_timeouts_stay(tmp_path):
    log = _record(tmp_path)
    scans, errors = _sdo(cananalyze.load(log).findings)
    assert len(scans) == 1
    msg = scans.message.iloc[0]
    assert msg.startswith("node-ID scan: SDO read of 0x1000:00 to 127 node-IDs (1-127), from +")
    assert "answered: node 2 (0x00060192), node 5 (0x00060192)" in msg
    assert "the 125 others sent nothing in the log (absent, not a fault)" in msg
    assert sorted(zip(errors.node, errors.message, strict=True)) == AFTER
    # the same log by the command line: check passes on the scan, fails on the two reads
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", log],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 1 and "node-ID scan" in out.stdout
    assert out.stdout.count("[error] sdo:") == 2


def test_a_declared_node_that_does_not_answer_is_a_finding(tmp_path):
    """Node 9 is declared (--device): its silence during the scan is a fault, not absence."""
    log = _record(tmp_path)
    scans, errors = _sdo(cananalyze.load(log, device={9: "cia402"}).findings)
    assert len(scans) == 1 and "to 126 node-IDs (1-8, 10-127)" in scans.message.iloc[0]
    assert sorted(zip(errors.node, errors.message, strict=True)) == [
        (5, "SDO upload 0x1018:01 abort: SDO protocol timed out"),
        (9, NO_ANSWER),
        (9, "SDO upload 0x1018:01 abort: SDO protocol timed out"),
    ]


def test_a_few_unanswered_reads_are_no_scan(tmp_path):
    """search(5) probes node-IDs 1-5: three silent ones are under SCAN_MIN, each a finding."""
    log = _record(tmp_path, limit=5)
    scans, errors = _sdo(cananalyze.load(log).findings)
    assert scans.empty
    timeouts = errors[errors.message.str.contains("0x1000:00")]
    assert sorted(timeouts.node) == [1, 3, 4]
    assert set(timeouts.message) == {NO_ANSWER}
    assert sorted(zip(errors.node, errors.message, strict=True)) == sorted(
        [*AFTER, *zip(timeouts.node, timeouts.message, strict=True)]
    )
