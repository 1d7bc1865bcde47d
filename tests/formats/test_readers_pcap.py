"""pcap and pcapng of SocketCAN: files written by scapy (and, for the Linux cooked
captures, by a small writer here), read back by scapy and by tshark when installed
(the independent readers), and bad files that must give one line."""

from __future__ import annotations

import shutil
import struct
import subprocess
import sys

import numpy as np
import pytest

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_BRS, FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX
from cananalyze.formats.source import read_all

scapy_all = pytest.importorskip("scapy.all")
from scapy.layers.can import CAN, CANFD  # noqa: E402
from scapy.layers.l2 import CookedLinux, CookedLinuxV2  # noqa: E402

TSHARK = shutil.which("tshark")


def _packets(n: int = 300, seed: int = 5):
    """Classic, extended, remote and error frames, and CAN FD with BRS, at known times."""
    rng = np.random.default_rng(seed)
    pkts, want = [], []
    for i in range(n):
        kind = i % 5
        data = rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8).tobytes()
        if kind == 0:
            p, w = (
                CAN(identifier=0x180 + i % 127, length=len(data), data=data),
                (0x180 + i % 127, 0, data),
            )
        elif kind == 1:
            ident = int(rng.integers(0x800, 0x1FFFFFFF))
            p = CAN(identifier=ident, flags="extended", length=len(data), data=data)
            w = (ident, FLAG_EXT, data)
        elif kind == 2:
            p, w = (
                CAN(identifier=0x701, flags="remote_transmission_request", length=1),
                (0x701, FLAG_RTR, b""),
            )
        elif kind == 3:
            err = bytes([0, 0x04, 0x19, 0x03, 0, 0, 7, 9])
            p = CAN(identifier=0x08A, flags="error", length=8, data=err)
            w = (0x08A, FLAG_ERR, err)
        else:
            fd = rng.integers(0, 256, 24, dtype=np.uint8).tobytes()
            p = CANFD(identifier=0x123, length=24, fd_flags="bit_rate_switch", data=fd)
            w = (0x123, FLAG_FD | FLAG_BRS, fd)
        p.time = 1_700_000_000 + i * 0.001
        pkts.append(p)
        want.append((p.time, *w))
    return pkts, want


def _check(fb, want) -> None:
    assert len(fb) == len(want)
    for i, (t, ident, flags, data) in enumerate(want):
        assert fb.t[i] == pytest.approx(float(t), abs=1e-6)
        assert int(fb.can_id[i]) == ident
        assert int(fb.flags[i]) & (FLAG_EXT | FLAG_RTR | FLAG_ERR | FLAG_FD | FLAG_BRS) == flags
        if flags & FLAG_RTR:
            assert int(fb.dlc[i]) == 1
        else:
            assert fb.payload(i) == data


@pytest.mark.parametrize("writer", ["wrpcap", "wrpcapng"])
def test_scapy_capture_reads_as_written(tmp_path, writer):
    pkts, want = _packets()
    path = tmp_path / ("bus." + ("pcap" if writer == "wrpcap" else "pcapng"))
    getattr(scapy_all, writer)(str(path), pkts)
    fb = read_all(path)
    _check(fb, want)
    # scapy's own reader of the same file agrees too (identifier, length, bytes)
    back = scapy_all.rdpcap(str(path))
    assert [int(p.identifier) for p in back] == fb.can_id.tolist()


def _tshark(path, *fields):
    out = subprocess.run(
        [
            TSHARK,
            "-r",
            str(path),
            "-T",
            "fields",
            "-E",
            "separator=;",
            *sum((["-e", f] for f in fields), []),
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return [line.split(";") for line in out.splitlines()]


@pytest.mark.skipif(TSHARK is None, reason="tshark not installed")
@pytest.mark.parametrize("writer", ["wrpcap", "wrpcapng"])
def test_same_as_tshark(tmp_path, writer):
    pkts, _ = _packets(120)
    path = tmp_path / "bus.cap"
    getattr(scapy_all, writer)(str(path), pkts)
    fb = read_all(path)
    rows = _tshark(
        path,
        "frame.time_epoch",
        "can.id",
        "can.flags.xtd",
        "can.flags.rtr",
        "can.flags.err",
        "can.len",
    )
    assert len(rows) == len(fb)
    for i, (t, cid, xtd, rtr, err, length) in enumerate(rows):
        assert float(t) == pytest.approx(fb.t[i], abs=1e-6)
        assert (err in ("1", "True")) == bool(fb.flags[i] & FLAG_ERR)
        if err in ("1", "True"):
            continue  # tshark gives the classes (test below), no identifier
        assert int(cid) == fb.can_id[i]
        # (scapy writes CAN FD without the FDF flag: tshark shows it as CAN of len 24)
        assert int(length) == (1 if fb.flags[i] & FLAG_RTR else fb.dlc[i])
        assert (xtd in ("1", "True")) == bool(fb.flags[i] & FLAG_EXT)
        assert (rtr in ("1", "True")) == bool(fb.flags[i] & FLAG_RTR)


@pytest.mark.skipif(TSHARK is None, reason="tshark not installed")
def test_error_classes_as_tshark_names_them(tmp_path):
    """The error classes of pcap error frames in JSONL, against tshark's can.err.* flags."""
    import json

    frames = [
        (0x004, bytes([0, 0x04, 0, 0, 0, 0, 0, 0])),  # controller: rx warning
        (0x08A, bytes([5, 0, 0x19, 0x03, 0, 0, 0, 0])),  # lost arb, protocol violation, bus error
        (0x240, bytes([0, 0, 0, 0, 0, 0, 10, 15])),  # bus-off, counters
        (0x020, bytes(8)),  # no ack
    ]
    pkts = []
    for k, (cls, data) in enumerate(frames):
        p = CAN(identifier=cls, flags="error", length=8, data=data)
        p.time = 10 + k
        pkts.append(p)
    path = tmp_path / "err.pcap"
    scapy_all.wrpcap(str(path), pkts)
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(path), "--format", "jsonl"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    recs = [json.loads(line) for line in out.splitlines() if '"frame"' in line]
    names = {
        "can.err.lostarb": "lost-arbitration",
        "can.err.ctrl": "controller-problem",
        "can.err.prot": "protocol-violation",
        "can.err.ack": "no-acknowledgement-on-tx",
        "can.err.busoff": "bus-off",
        "can.err.buserror": "bus-error",
        "can.err.ctrl.rx_warning": "rx-error-warning",
        "can.err.prot.type.bit": "single-bit-error",
        "can.err.prot.type.bit0": "tx-dominant-bit-error",
        "can.err.prot.type.bit1": "tx-recessive-bit-error",
    }
    rows = _tshark(path, *names, "can.err.lostarb.bitnum")
    assert len(rows) == len(recs) == 4
    for rec, row in zip(recs, rows, strict=True):
        said = {names[f] for f, v in zip(names, row[:-1], strict=True) if v in ("1", "True")}
        ours = set(rec["error_classes"]) | set(rec.get("controller", ()))
        ours |= set(rec.get("protocol", {}).get("types", ()))
        assert ours - {"error-counter-tx-rx"} == said, rec
        if "lost_arbitration_bit" in rec:
            assert rec["lost_arbitration_bit"] == int(row[-1])
    assert recs[2]["tx_errors"] == 10 and recs[2]["rx_errors"] == 15


def _le_frame(cid: int, data: bytes) -> bytes:
    """struct can_frame in host (little-endian) order, as a Linux cooked capture holds it."""
    return struct.pack("<IBBBB", cid, len(data), 0, 0, 0) + data.ljust(8, b"\0")


@pytest.mark.parametrize("cooked", ["sll", "sll2"])
def test_linux_cooked_capture(tmp_path, cooked):
    pkts = []
    for k in range(50):
        payload = _le_frame(0x181 + k % 3, bytes([k, k + 1]))
        if cooked == "sll":
            p = CookedLinux(pkttype=4 if k % 2 else 0, lladdrtype=280, proto=0x000C) / payload
        else:
            p = CookedLinuxV2(proto=0x000C, lladdrtype=280, pkttype=4 if k % 2 else 0) / payload
        p.time = 100 + k * 0.01
        pkts.append(p)
    # a non-CAN packet of an "any" capture is skipped, not an error
    head = CookedLinux(proto=0x0800) if cooked == "sll" else CookedLinuxV2(proto=0x0800)
    other = head / (b"\x45" * 20)
    other.time = 99
    path = tmp_path / "any.pcap"
    scapy_all.wrpcap(str(path), [other, *pkts])
    fb = read_all(path)
    assert len(fb) == 50
    assert fb.can_id.tolist() == [0x181 + k % 3 for k in range(50)]
    assert [fb.payload(k) for k in range(50)] == [bytes([k, k + 1]) for k in range(50)]
    assert ((fb.flags & FLAG_TX) != 0).tolist() == [bool(k % 2) for k in range(50)]
    if TSHARK:
        rows = _tshark(path, "can.id", "data.data")
        assert [int(r[0]) for r in rows if r[0]] == fb.can_id.tolist()


def test_other_link_type_is_one_line(tmp_path):
    from scapy.layers.inet import IP
    from scapy.layers.l2 import Ether

    path = tmp_path / "eth.pcap"
    scapy_all.wrpcap(str(path), [Ether() / IP()])
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(path)], capture_output=True, text=True
    )
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        f"cananalyze: error: {path}: a capture of link type 1 (Ethernet), not of CAN: "
        "cananalyze reads SocketCAN (227) and Linux cooked captures (113, 276) of CAN"
    ]
    png = tmp_path / "eth.pcapng"
    scapy_all.wrpcapng(str(png), [Ether() / IP()])
    with pytest.raises(InputError, match="link type 1"):
        read_all(png)


def _pcap(records: list[bytes], snaplen: int = 0x40000) -> bytes:
    head = struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, snaplen, 227)
    body = b""
    for k, frame in enumerate(records):
        body += struct.pack("<IIII", 1000 + k, 0, len(frame), len(frame)) + frame
    return head + body


def _be_frame(cid: int, data: bytes) -> bytes:
    return struct.pack(">IBBBB", cid, len(data), 0, 0, 0) + data.ljust(8, b"\0")


def test_absurd_record_length_is_bounded(tmp_path):
    good = _pcap([_be_frame(0x181, b"\x01")] * 3)
    bad = struct.pack("<IIII", 2000, 0, 0x7FFFFFF0, 0x7FFFFFF0) + b"\0" * 16
    path = tmp_path / "bad.pcap"
    path.write_bytes(good + bad + _pcap([_be_frame(0x182, b"")])[24:])
    fb = read_all(path)
    # what came before is kept, and the reader finds the record after the damage again
    assert fb.can_id.tolist() == [0x181] * 3 + [0x182]
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(path)], capture_output=True, text=True
    )
    assert r.returncode == 0
    assert f"{path}:offset {len(good)}: pcap record of 2147483632 bytes is longer than" in r.stderr
    assert "skipped 32 bytes to the next plausible record" in r.stderr
    strict = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", "--strict", str(path)],
        capture_output=True,
        text=True,
    )
    assert strict.returncode == 2 and "Traceback" not in strict.stderr


def test_capture_with_a_cr_byte_and_no_lf_byte(tmp_path):
    """The CR-only line ends of classic Mac text logs are turned into newlines; a small
    capture whose bytes hold a 0x0D and no 0x0A was translated too (its record lengths
    of 13 read as 10)."""
    frames = [_be_frame(0x181, bytes(range(1, 6))), _be_frame(0x182, b"\x0d\x0d")]
    data = _pcap([f[:13] for f in frames])
    assert b"\r" in data and b"\n" not in data
    path = tmp_path / "cr.pcap"
    path.write_bytes(data)
    fb = read_all(path)
    assert fb.can_id.tolist() == [0x181, 0x182]
    assert [fb.payload(0), fb.payload(1)] == [bytes(range(1, 6)), b"\x0d\x0d"]


def test_cut_file_keeps_whole_records(tmp_path):
    data = _pcap([_be_frame(0x181 + k, bytes([k])) for k in range(10)])
    path = tmp_path / "cut.pcap"
    path.write_bytes(data[:-7])
    fb = read_all(path)
    assert fb.can_id.tolist() == [0x181 + k for k in range(9)]


def test_absurd_pcapng_block_is_bounded(tmp_path):
    pkts, _ = _packets(10)
    path = tmp_path / "b.pcapng"
    scapy_all.wrpcapng(str(path), pkts)
    raw = path.read_bytes() + struct.pack("<II", 6, 0xFFFFFFF0) + b"\0" * 32
    path.write_bytes(raw)
    fb = read_all(path)
    assert len(fb) == 10
    with pytest.raises(InputError, match="pcapng block of 4294967280 bytes is impossible"):
        read_all(path, strict=True)


def test_large_capture_is_the_candump_log(tmp_path):
    """200k frames: pcap and the candump log of the same frames read the same."""
    rng = np.random.default_rng(1)
    n = 200_000
    ids = rng.integers(0x80, 0x7FF, n)
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    dlc = rng.integers(0, 9, n)
    data[np.arange(8)[None, :] >= dlc[:, None]] = 0
    rec = np.zeros(n, [("sec", "<u4"), ("usec", "<u4"), ("incl", "<u4"), ("orig", "<u4"),
                       ("id", ">u4"), ("len", "u1"), ("pad", "u1", 3), ("data", "u1", 8)])  # fmt: skip
    rec["sec"] = 1000 + np.arange(n)
    rec["incl"] = rec["orig"] = 16
    rec["id"], rec["len"], rec["data"] = ids, dlc, data
    path = tmp_path / "big.pcap"
    path.write_bytes(_pcap([]) + rec.tobytes())
    log = tmp_path / "big.log"
    hexes = [data[k, : dlc[k]].tobytes().hex().upper() for k in range(n)]
    log.write_text("".join(f"({1000 + k}.000000) can0 {ids[k]:03X}#{hexes[k]}\n" for k in range(n)))
    a, b = read_all(path), read_all(log)
    assert np.array_equal(a.can_id, b.can_id) and np.array_equal(a.dlc, b.dlc)
    assert np.array_equal(a.data, b.data) and np.allclose(a.t, b.t)


@pytest.mark.parametrize("writer", ["wrpcap", "wrpcapng"])
def test_cut_at_every_offset_keeps_a_prefix(tmp_path, writer):
    pkts, _ = _packets(12)
    path = tmp_path / "full.cap"
    getattr(scapy_all, writer)(str(path), pkts)
    data = path.read_bytes()
    full = read_all(path)
    cut = tmp_path / "cut.cap"
    for n in range(len(data)):
        cut.write_bytes(data[:n])
        try:
            got = read_all(cut)
        except InputError:
            continue  # too short to be recognised: one line, no traceback
        k = len(got)
        assert k <= len(full)
        assert got.can_id.tolist() == full.can_id.tolist()[:k]
        assert [got.payload(i) for i in range(k)] == [full.payload(i) for i in range(k)]


@pytest.mark.parametrize("writer", ["wrpcap", "wrpcapng"])
def test_mutated_captures_never_crash(tmp_path, writer):
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    pkts, _ = _packets(30)
    path = tmp_path / "base.cap"
    getattr(scapy_all, writer)(str(path), pkts)
    base = path.read_bytes()

    @settings(max_examples=150, deadline=None, suppress_health_check=list(HealthCheck))
    @given(st.lists(st.tuples(st.integers(0, len(base) - 1), st.integers(0, 255)), max_size=12))
    def check(flips):
        data = bytearray(base)
        for at, value in flips:
            data[at] = value
        p = tmp_path / "m.cap"
        p.write_bytes(bytes(data))
        try:
            fb = read_all(p)
        except InputError:
            return
        assert len(fb) <= 30 and (fb.dlc <= 64).all()

    check()
