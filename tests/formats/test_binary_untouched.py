"""A binary log's bytes are read as written: the CR-only line-end repair is for text
formats alone (issue 38). A pcap whose head has a 0x0D and no 0x0A had every 0x0D made
0x0A: the frame at 1.200000 s (microseconds 0x00030D40) read as 1.199232 s.

Only pcap can meet the condition: a BLF's first object is a container (type 10, 0x0A),
a pcapng starts with the block type 0x0A0D0D0A and an MCAP with "\\x89MCAP0\\r\\n", so
their heads always hold a 0x0A. A CR-only text log is still repaired (last test).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from cananalyze.formats.source import read_all

scapy_all = pytest.importorskip("scapy.all")
from scapy.layers.can import CAN  # noqa: E402

TIMES = [1.2, 1.3, 13.0 + 0x0D0D / 1e6]  # microseconds 0x00030D40, 0x000493E0, 0x00000D0D
DATA = bytes([0x0D, 0x0D, 1, 2, 3, 4, 5, 6])


def _pcap(path, nano: bool = False) -> None:
    pkts = []
    for i, t in enumerate(TIMES):
        p = CAN(identifier=0x181 + i, length=8, data=DATA)
        p.time = t
        pkts.append(p)
    scapy_all.wrpcap(str(path), pkts, linktype=227, nano=nano)
    raw = path.read_bytes()
    assert b"\r" in raw and b"\n" not in raw  # the case: a 0x0D and no 0x0A in the head


def _expected(path):
    """scapy's reader of the same file: the independent answer."""
    return [(float(p.time), int(p.identifier), bytes(p.data)) for p in scapy_all.rdpcap(str(path))]


@pytest.mark.parametrize("nano", [False, True])
def test_pcap_with_cr_and_no_newline_reads_as_written(tmp_path, nano):
    path = tmp_path / "cr.pcap"
    _pcap(path, nano)
    fb = read_all(path)
    got = [(float(fb.t[i]), int(fb.can_id[i]), fb.payload(i)) for i in range(len(fb))]
    want = _expected(path)
    assert len(got) == len(want) == 3
    for (t, ident, data), (wt, wident, wdata) in zip(got, want, strict=True):
        assert t == pytest.approx(wt, abs=1e-9)
        assert (ident, data) == (wident, wdata) and data == DATA


def test_forced_format_and_a_pipe_read_the_bytes_as_written(tmp_path):
    path = tmp_path / "cr.pcap"
    _pcap(path)
    fb = read_all(path, fmt="pcap")
    assert fb.t.tolist() == pytest.approx([t for t, _, _ in _expected(path)], abs=1e-9)
    # standard input is not seekable: the head read for detection is replayed to the reader
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", "-", "--format", "jsonl"],
        stdin=path.open("rb"),
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    frames = [json.loads(line) for line in out.splitlines()]
    frames = [f for f in frames if f.get("kind") == "frame"]
    assert [f["t"] for f in frames] == pytest.approx(TIMES, abs=1e-9)
    assert {f["data"] for f in frames} == {DATA.hex()}


def test_cr_only_text_log_is_still_repaired(tmp_path):
    path = tmp_path / "mac.log"
    lines = [f"({t:.6f}) can0 18{i + 1}#0D0D010203040506" for i, t in enumerate(TIMES)]
    path.write_bytes("\r".join(lines).encode() + b"\r")
    fb = read_all(path)
    assert len(fb) == 3 and fb.t.tolist() == pytest.approx(TIMES, abs=1e-6)
    assert fb.payload(0) == DATA
