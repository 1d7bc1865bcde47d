"""Loop-back echoes in Linux cooked captures are one frame, not two (issue 37).

The traffic is python-canopen's: a master (the capturing host) reads and writes a CiA 402
drive's objects over SDO and sends NMT; the drive (a LocalNode) answers. The capture is
written as Wireshark's Linux cooked captures (scapy's SLL in pcap, SLL2 in pcapng) the way
Linux hands them to it: each frame the host sends appears as it goes out (pkttype 4) and
again, a moment later, as its loop-back echo (pkttype 0); the drive's frames once.
"""

from __future__ import annotations

import logging
import struct
import subprocess
import sys

import can
import canopen
import numpy as np
import pytest

import cananalyze
from cananalyze.core.frames import FLAG_TX
from cananalyze.formats.source import read_all
from tests.conftest import real_file
from tests.helpers.virtual_bus import drain, patient_client, unique_channel

scapy_all = pytest.importorskip("scapy.all")
from scapy.layers.l2 import CookedLinux, CookedLinuxV2  # noqa: E402

SLAVE_EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"
ECHO_AFTER_S = 0.0002  # the controller's report that the frame went out


def _traffic() -> tuple[list[can.Message], set[int]]:
    """python-canopen's frames, and the identifiers the master sent."""
    logging.getLogger("canopen").setLevel(logging.ERROR)
    channel = unique_channel("echo")
    recorder = can.Bus(interface="virtual", channel=channel)
    server_net, client_net = canopen.Network(), canopen.Network()
    server_net.connect(interface="virtual", channel=channel)
    client_net.connect(interface="virtual", channel=channel)
    try:
        drive = canopen.LocalNode(5, str(real_file(SLAVE_EDS)))
        server_net.add_node(drive)
        master = patient_client(5)
        client_net.add_node(master)
        master.nmt.state = "PRE-OPERATIONAL"
        for _ in range(3):  # the same request three times: three transfers, three echoes
            assert int.from_bytes(master.sdo.upload(0x1000, 0), "little") == 0x00060192
        master.sdo.download(0x6060, 0, b"\x01")
        master.sdo.upload(0x1018, 1)
        frames = drain(recorder)
    finally:
        server_net.disconnect()
        client_net.disconnect()
        recorder.shutdown()
    return frames, {0x605, 0x000}


def _le_frame(m: can.Message) -> bytes:
    """struct can_frame in host (little-endian) order, as a Linux cooked capture holds it."""
    return struct.pack("<IBBBB", m.arbitration_id, m.dlc, 0, 0, 0) + bytes(m.data).ljust(8, b"\0")


def _capture(path, frames, sent: set[int], cooked: str) -> int:
    """Write the capture; the number of echoes in it."""
    pkts, echoes = [], 0

    def packet(m, pkttype, t):
        if cooked == "sll":
            p = CookedLinux(pkttype=pkttype, lladdrtype=280, proto=0x000C) / _le_frame(m)
        else:
            p = CookedLinuxV2(proto=0x000C, lladdrtype=280, pkttype=pkttype) / _le_frame(m)
        p.time = t
        return p

    for m in frames:
        if m.arbitration_id in sent:
            pkts.append(packet(m, 4, m.timestamp))
            pkts.append(packet(m, 0, m.timestamp + ECHO_AFTER_S))
            echoes += 1
        else:
            pkts.append(packet(m, 0, m.timestamp))
    pkts.sort(key=lambda p: float(p.time))
    (scapy_all.wrpcap if cooked == "sll" else scapy_all.wrpcapng)(str(path), pkts)
    return echoes


@pytest.mark.parametrize("cooked", ["sll", "sll2"])
def test_each_sent_frame_once_and_no_sdo_timeout(tmp_path, cooked):
    frames, sent = _traffic()
    path = tmp_path / ("host.pcap" if cooked == "sll" else "host.pcapng")
    echoes = _capture(path, frames, sent, cooked)
    assert echoes >= 6
    assert len(scapy_all.rdpcap(str(path))) == len(frames) + echoes  # scapy sees both copies
    fb = read_all(path)
    # the frames python-canopen put on the bus, each once; the master's marked as sent
    assert len(fb) == len(frames)
    assert fb.can_id.tolist() == [m.arbitration_id for m in frames]
    assert [fb.payload(i) for i in range(len(fb))] == [bytes(m.data) for m in frames]
    tx = (fb.flags & FLAG_TX) != 0
    assert tx.tolist() == [m.arbitration_id in sent for m in frames]
    assert np.allclose(fb.t, [m.timestamp for m in frames], atol=1e-6)
    cap = cananalyze.load(path)
    assert len(cap.sdo) == 5 and set(cap.sdo.result) == {"ok"}
    assert cap.findings[cap.findings.rule == "sdo"].empty
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0 and "timeout" not in out.stdout
    assert f"{echoes} loop-back echoes" in out.stderr


def test_the_same_frame_from_the_bus_later_is_kept(tmp_path):
    """A received frame like a sent one but outside the echo window is traffic: kept."""
    sent = can.Message(timestamp=10.0, arbitration_id=0x605, data=b"\x40\x00\x10\x00\0\0\0\0")
    path = tmp_path / "late.pcapng"
    pkts = []
    for pkttype, t in ((4, 10.0), (0, 10.0002), (0, 11.0)):  # out, its echo, a second one
        p = CookedLinuxV2(proto=0x000C, lladdrtype=280, pkttype=pkttype) / _le_frame(sent)
        p.time = t
        pkts.append(p)
    scapy_all.wrpcapng(str(path), pkts)
    fb = read_all(path)
    assert fb.t.tolist() == pytest.approx([10.0, 11.0])
    assert ((fb.flags & FLAG_TX) != 0).tolist() == [True, False]
