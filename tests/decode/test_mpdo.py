"""MPDO (CiA 301 multiplexed PDO) end to end: the mapping's count (0xFF DAM, 0xFE SAM) written
by python-canopen's SDO client over python-can's virtual bus (frames re-timed here), the MPDO
frames encoded as Lely's lely-core sends them (commit 620d1858, src/co/tpdo.c lines 710-715:
DAM `data[0] = id | 0x80`; lines 773-776: SAM `data[0] = id`, the producer's node-ID; then
the index little-endian, the sub-index, 4 bytes of value, 8 bytes in all), decoded into
the address, the object and its value, named and typed by the object's node.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import canopen
import pytest
from canopen.objectdictionary import UNSIGNED8, UNSIGNED32, UNSIGNED64, ODRecord

import cananalyze
from tests.helpers.virtual_bus import sdo_download_frames, variable

ROOT = Path(__file__).resolve().parents[2]
PRODUCER = 5


def _od() -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()
    for n in (0, 1):
        mapping = ODRecord(f"TPDO{n + 1} mapping parameter", 0x1A00 + n)
        mapping.add_member(variable(0x1A00 + n, 0, "Number of entries", UNSIGNED8, "rw", 0))
        mapping.add_member(variable(0x1A00 + n, 1, "Entry 1", UNSIGNED32, "rw", 0))
        od.add_object(mapping)
    return od


def dam(node: int, index: int, sub: int, value: bytes) -> bytes:
    """co_dam_mpdo_event's frame (lely-core src/co/tpdo.c lines 710-715)."""
    return bytes([node | 0x80]) + struct.pack("<HB", index, sub) + value.ljust(4, b"\0")


def sam(producer: int, index: int, sub: int, value: bytes) -> bytes:
    """co_sam_mpdo_event's frame (lely-core src/co/tpdo.c lines 773-776)."""
    return bytes([producer]) + struct.pack("<HB", index, sub) + value.ljust(4, b"\0")


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    """TPDO1 of node 5 a DAM MPDO, TPDO2 a SAM MPDO."""
    writes = sdo_download_frames(PRODUCER, _od(), [(0x1A00, 0, 0xFF, 1), (0x1A01, 0, 0xFE, 1)])
    rows = [(0.1 + 0.001 * k, cid, data) for k, (cid, data) in enumerate(sum(writes, []))]
    rows += [
        (0.5, 0x000, bytes([0x01, 0x00])),
        (1.0, 0x185, dam(6, 0x6040, 0, b"\x0f\x00")),  # controlword 0x000F to node 6
        (1.1, 0x185, dam(0, 0x6200, 1, b"\x13")),  # to every node
        (1.2, 0x285, sam(PRODUCER, 0x1017, 0, b"\xe8\x03\xff\xff")),  # UNSIGNED16 1000
        (1.3, 0x185, dam(6, 0x6040, 0, b"\x06\x00")),
        (1.4, 0x185, dam(6, 0x6040, 0, b"")[:3]),  # short: not an MPDO frame
    ]
    path = tmp_path_factory.mktemp("mpdo") / "mpdo.log"
    text = [f"({t:.6f}) can0 {cid:03X}#{data.hex().upper()}" for t, cid, data in rows]
    path.write_text("\n".join(text) + "\n")
    return path


def test_mpdo_signals_are_the_objects_the_frames_carry(log):
    cap = cananalyze.load(log, device={6: "cia402", PRODUCER: "cia401"})
    s = cap.signals
    assert set(s.pdo) == {"tpdo1", "tpdo2"} and set(s.node) == {PRODUCER}
    got = list(zip(s.t.round(3), s.signal, s.value, strict=True))
    assert got == [
        (1.0, "controlword", 15),  # named by node 6's CiA 402 profile
        (1.1, "digital_outputs_1_8", 0x13),  # to all nodes: the producer's profile names it
        (1.2, "obj_1017_00", 1000),  # CiA 301's UNSIGNED16: the upper 2 bytes not the value
        (1.3, "controlword", 6),
    ]
    f = cap.findings
    assert list(f.rule) == ["pdo_length"] and f.measured[0] == 3 and f.expected[0] == 8


def test_mpdo_in_text_and_jsonl(log):
    run = [sys.executable, "-m", "cananalyze", "decode", str(log)]
    text = subprocess.run(run, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert "TPDO1 MPDO to node 6 0x6040:00  obj_6040_00=15" in text
    assert "TPDO1 MPDO to all nodes 0x6200:01  obj_6200_01=19" in text
    assert "TPDO2 MPDO from node 5 0x1017:00  obj_1017_00=1000" in text
    assert "[DLC 3 shorter than the 8 bytes of an MPDO (TPDO1): not decoded]" in text
    out = subprocess.run(
        [*run, "--format", "jsonl"], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout
    frames = [r for r in map(json.loads, out.splitlines()) if r.get("service") == "tpdo"]
    assert [r.get("mpdo") for r in frames] == [
        {"mode": "dam", "destination": 6, "index": 0x6040, "subindex": 0},
        {"mode": "dam", "destination": 0, "index": 0x6200, "subindex": 1},
        {"mode": "sam", "producer": PRODUCER, "index": 0x1017, "subindex": 0},
        {"mode": "dam", "destination": 6, "index": 0x6040, "subindex": 0},
        None,
    ]
    assert frames[2]["signals"] == {"obj_1017_00": 1000}
    assert "pdo_problem" in frames[4] and "signals" not in frames[4]


def test_sam_value_dispatched_to_the_consumer_object(tmp_path):
    """Node 6's object dispatching list (0x1FD0:1, written in the log) takes node 5's
    0x2000:01..02 into its 0x6200:01..02 (a block of 2): a SAM frame's value is named and
    typed as node 6's object (its CiA 401 profile), and the text says where it went."""
    od = canopen.ObjectDictionary()
    lst = ODRecord("Object dispatching list 1", 0x1FD0)
    lst.add_member(variable(0x1FD0, 0, "Number of entries", UNSIGNED8, "rw", 1))
    lst.add_member(variable(0x1FD0, 1, "Entry 1", UNSIGNED64, "rw", 0))
    od.add_object(lst)
    # block 2 | consumer 0x6200:01 | producer 0x2000:01 of node 5 (CiA 301 / lely's layout)
    entry = (2 << 56) | (0x6200 << 40) | (0x01 << 32) | (0x2000 << 16) | (0x01 << 8) | PRODUCER
    (frames,) = sdo_download_frames(6, od, [(0x1FD0, 1, entry, 8)], expedited=False)
    (count,) = sdo_download_frames(PRODUCER, _od(), [(0x1A01, 0, 0xFE, 1)])
    rows = [(0.1 + 0.001 * k, cid, data) for k, (cid, data) in enumerate(frames + count)]
    rows += [
        (1.0, 0x285, sam(PRODUCER, 0x2000, 2, b"\x81")),  # 0x2000:02 -> node 6's 0x6200:02
        (1.1, 0x285, sam(PRODUCER, 0x2000, 3, b"\x07")),  # past the block: not dispatched
    ]
    log = tmp_path / "sam.log"
    text = [f"({t:.6f}) can0 {cid:03X}#{data.hex().upper()}" for t, cid, data in rows]
    log.write_text("\n".join(text) + "\n")
    cap = cananalyze.load(log, device={6: "cia401"})
    got = list(zip(cap.signals.t.round(3), cap.signals.signal, cap.signals.value, strict=True))
    assert got == [(1.0, "digital_outputs_9_16", 0x81), (1.1, "obj_2000_03", 7)]
    run = [sys.executable, "-m", "cananalyze", "decode", str(log), "--device", "6=cia401"]
    out = subprocess.run(run, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert "TPDO2 MPDO from node 5 0x2000:02 -> node 6 0x6200:02  digital_outputs_9_16=129" in out
    assert "TPDO2 MPDO from node 5 0x2000:03  obj_2000_03=7" in out
    assert "SDO write 0x1FD0:01 Object dispatching list 1: entry 1" in out


# node 5's object scanner list 1, entry 1 (CiA 301 v4.2.0 7.5.2, objects 1FA0h-1FCFh,
# UNSIGNED32): block size 2 (bits 24-31) | index 0x2000 (bits 8-23) | first sub-index 1 (0-7)
SCANNER_ENTRY = (2 << 24) | (0x2000 << 8) | 0x01


def _scanner_log(tmp_path: Path, config: list) -> Path:
    rows = [(0.1 + 0.001 * k, cid, data) for k, (cid, data) in enumerate(config)]
    rows += [
        (1.0, 0x285, sam(PRODUCER, 0x2000, 2, b"\x81")),  # within the scanner list's block
        (1.1, 0x285, sam(PRODUCER, 0x2000, 3, b"\x07")),  # past it: not the node's to send
    ]
    log = tmp_path / "scan.log"
    text = [f"({t:.6f}) can0 {cid:03X}#{data.hex().upper()}" for t, cid, data in rows]
    log.write_text("\n".join(text) + "\n")
    return log


def _sam_frames(log: Path, *extra: str) -> list[dict]:
    run = [sys.executable, "-m", "cananalyze", "decode", str(log), "--format", "jsonl", *extra]
    out = subprocess.run(run, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    return [r for r in map(json.loads, out.splitlines()) if r.get("service") == "tpdo"]


def test_sam_object_checked_against_the_producers_scanner_list_from_the_log(tmp_path):
    """The scanner list written by python-canopen's SDO client (segmented: UNSIGNED32 as 4
    bytes expedited would do too) says node 5 may send 0x2000:01..02: a SAM frame of
    0x2000:03 is marked, in JSONL (`mpdo.scanned`) and the text."""
    od = _od()
    lst = ODRecord("Object scanner list 1", 0x1FA0)
    lst.add_member(variable(0x1FA0, 0, "Number of entries", UNSIGNED8, "rw", 1))
    lst.add_member(variable(0x1FA0, 1, "Entry 1", UNSIGNED32, "rw", 0))
    od.add_object(lst)
    writes = sdo_download_frames(
        PRODUCER, od, [(0x1FA0, 1, SCANNER_ENTRY, 4), (0x1FA0, 0, 1, 1), (0x1A01, 0, 0xFE, 1)]
    )
    log = _scanner_log(tmp_path, sum(writes, []))
    frames = _sam_frames(log)
    assert [f["mpdo"].get("scanned") for f in frames] == [True, False]
    run = [sys.executable, "-m", "cananalyze", "decode", str(log)]
    out = subprocess.run(run, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert "MPDO from node 5 0x2000:02  obj_2000_02=129" in out
    assert "MPDO from node 5 0x2000:03  [not in node 5's object scanner list]" in out
    assert "SDO write 0x1FA0:01 Object scanner list 1: entry 1" in out


def test_scanner_list_and_sam_mode_from_the_network_file(tmp_path):
    """The network file's `object_scanner_list` and a TPDO's `mpdo = "sam"` (no SDO in the
    log) configure the same; without a scanner list nothing is marked."""
    net = tmp_path / "net.toml"
    net.write_text(
        f"[nodes.{PRODUCER}]\nobject_scanner_list = [0x{SCANNER_ENTRY:08X}]\n"
        f'[nodes.{PRODUCER}.tpdo.2]\nmpdo = "sam"\n'
    )
    log = _scanner_log(tmp_path, [])
    frames = _sam_frames(log, "--network", str(net))
    assert [f["mpdo"].get("scanned") for f in frames] == [True, False]
    assert [f["signals"] for f in frames] == [{"obj_2000_02": 0x81}, {"obj_2000_03": 7}]
    net.write_text(f'[nodes.{PRODUCER}.tpdo.2]\nmpdo = "sam"\n')
    assert [f["mpdo"].get("scanned") for f in _sam_frames(log, "--network", str(net))] == [
        None,
        None,
    ]


def test_network_file_mpdo_errors_name_the_file(tmp_path):
    net = tmp_path / "net.toml"
    log = _scanner_log(tmp_path, [])
    for text, what in (
        (f'[nodes.{PRODUCER}.tpdo.2]\nmpdo = "both"\n', "mpdo"),
        (f"[nodes.{PRODUCER}]\nobject_scanner_list = [0x1FFFFFFFF]\n", "object_scanner_list"),
    ):
        net.write_text(text)
        run = [sys.executable, "-m", "cananalyze", "decode", str(log), "--network", str(net)]
        done = subprocess.run(run, capture_output=True, text=True, cwd=ROOT)
        assert done.returncode != 0 and "Traceback" not in done.stderr
        assert str(net) in done.stderr and what in done.stderr
