"""Words of the text output and `--summary` on python-canopen traffic (issue 44, item 13):
an NMT reset of one node, SDO latencies in node-ID order, NMT states only of nodes that
sent a frame."""

from __future__ import annotations

import logging
import subprocess
import sys

import can
import canopen

from tests.conftest import real_file
from tests.helpers.virtual_bus import drain, patient_client, unique_channel

SLAVE_EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"
OTHER_EDS = "jclinton830__canopen_test/roboteq_motor_controllers_v80.eds"


def _record(tmp_path) -> str:
    """Nodes 2, 10 and 15 answer SDO reads (15: another vendor's drive); the
    master resets node 32 and every node-ID 40-60 in turn, none of which is there."""
    logging.getLogger("canopen").setLevel(logging.ERROR)
    channel = unique_channel("words")
    recorder = can.Bus(interface="virtual", channel=channel)
    master = canopen.Network()
    master.connect(interface="virtual", channel=channel)
    servers = []
    try:
        for node, eds in ((2, SLAVE_EDS), (10, SLAVE_EDS), (15, OTHER_EDS)):
            net = canopen.Network()
            net.connect(interface="virtual", channel=channel)
            net.add_node(canopen.LocalNode(node, str(real_file(eds))))
            servers.append(net)
            client = patient_client(node)
            master.add_node(client)
            client.sdo.upload(0x1000, 0)
            client.sdo.upload(0x1018, 1)
        for node in (32, *range(40, 61)):
            master.send_message(0x000, bytes([0x81, node]))  # reset node
        frames = drain(recorder)
    finally:
        master.disconnect()
        for net in servers:
            net.disconnect()
        recorder.shutdown()
    path = tmp_path / "words.log"
    path.write_text(
        "".join(
            f"({m.timestamp:.6f}) can0 {m.arbitration_id:03X}#{m.data.hex().upper()}\n"
            for m in frames
        )
    )
    return str(path)


def _run(*args: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    )
    return out.stdout


def test_reset_node_sdo_order_nmt_states_and_unknown_devices(tmp_path):
    log = _record(tmp_path)
    text = _run("decode", log)
    assert "NMT reset node 32\n" in text and "node node" not in text
    summary = _run("decode", log, "--summary")
    sdo = summary[summary.index("SDO latency per node:") :].splitlines()[1:4]
    assert [line.split(":")[0].strip() for line in sdo] == ["node 2", "node 10", "node 15"]
    # nodes that only the master named (reset) have no NMT state line: none sent a frame
    assert "NMT state node" not in summary
