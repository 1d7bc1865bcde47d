"""Damaged binary logs: resynchronise, never invent a frame (issue 38, item 3).

Captures come from independent writers (python-can's BLFWriter, plain and zlib
containers; scapy's pcap and pcapng writers, SocketCAN link type 227), are damaged
the ways the fuzz campaign found (4 KiB zeroed in the middle, 16 bytes overwritten
inside a compressed container, one record or block length corrupted) and read back.
Against the independent reader of the intact file (python-can's BLFReader, scapy's
rdpcap), as (time, identifier, data):

(a) every frame read is one of the intact file's: none is invented;
(b) the frames away from the damage are all kept: those whose bytes the damage left
    whole and readable (for a zlib container: inflated from the bytes before the
    damage), except the one just before a damaged stretch, which the reader may refuse
    too (the damage may have begun inside it);
(c) a problem names the offset of the damage (the container it is in, or the record).
"""

from __future__ import annotations

import random
import re
import struct
import zlib

import can
import numpy as np
import pytest
from readers_util import run

from cananalyze.core.frames import FLAG_ERR
from cananalyze.formats.logs import blf, pcap
from cananalyze.formats.source import open_log

SAMPLES = __import__("pathlib").Path(__file__).resolve().parents[2] / "samples"
ZERO = 4096  # bytes zeroed in the middle


def _key(t: float, ident: int, data: bytes, error: bool = False) -> tuple:
    # error frames: python-can and this reader give their data bytes differently
    return (round(float(t), 6), int(ident), "error" if error else bytes(data))


def _keys(batch) -> list[tuple]:
    return [
        _key(batch.t[i], batch.can_id[i], batch.payload(i), bool(batch.flags[i] & FLAG_ERR))
        for i in range(len(batch))
    ]


def _offsets(problems) -> list[int]:
    """The file offsets the problems name (their location "offset N")."""
    out = []
    for p in problems.shown:
        m = re.fullmatch(r"offset (\d+)", p.location)
        if m:
            out.append(int(m.group(1)))
    return out


def _zeroed(data: bytes, at: int, n: int = ZERO) -> bytes:
    d = bytearray(data)
    d[at : at + n] = bytes(min(n, len(d) - at))
    return bytes(d)


# ------------------------------------------------------------------------------ BLF


def _messages(n: int, seed: int = 3) -> list[can.Message]:
    """Classic, extended and CAN FD data frames on two channels, 0.7 ms apart."""
    rnd = random.Random(seed)
    out = []
    for i in range(n):
        fd = i % 13 == 0
        ext = rnd.random() < 0.2
        size = rnd.choice([0, 8, 12, 32, 64]) if fd else rnd.randrange(9)
        out.append(
            can.Message(
                timestamp=1700000000.0 + i * 0.0007,
                arbitration_id=rnd.randrange(0x20000000 if ext else 0x800),
                is_extended_id=ext,
                is_fd=fd,
                data=bytes(rnd.randrange(256) for _ in range(size)),
                channel=rnd.randrange(2),
            )
        )
    return out


@pytest.fixture(scope="module", params=[0, 6], ids=["plain", "zlib"])
def written(request, tmp_path_factory):
    """A 12,000-frame BLF by python-can (5 containers of 128 KiB, records straddling
    them), its python-can frames as keys, in file order."""
    path = tmp_path_factory.mktemp("resync") / f"w{request.param}.blf"
    with can.BLFWriter(str(path), compression_level=request.param) as w:
        for m in _messages(12000):
            w.on_message_received(m)
    keys = [_key(m.timestamp, m.arbitration_id, m.data) for m in can.BLFReader(str(path))]
    return path, keys


def _layout(data: bytes) -> tuple[list[tuple], list[tuple[int, int]]]:
    """A sound BLF's containers (file offset, size, method, start and length of their
    data in the inflated stream, payload) and its objects (start, end in that stream)."""
    pos = struct.unpack_from("<L", data, 4)[0]
    conts, inner = [], bytearray()
    while pos + 16 <= len(data):
        size = struct.unpack_from("<L", data, pos + 8)[0]
        method = struct.unpack_from("<H", data, pos + 16)[0]
        payload = data[pos + 32 : pos + size]
        chunk = zlib.decompress(payload) if method == 2 else payload
        conts.append((pos, size, method, len(inner), len(chunk), payload))
        inner += chunk
        pos += size + size % 4
    objs, p = [], 0
    while p + 16 <= len(inner):
        size = struct.unpack_from("<L", inner, p + 8)[0]
        objs.append((p, p + size))
        p += size + size % 4
    return conts, objs


def _kept_whole(data: bytes, lo: int, hi: int) -> tuple[set[int], int]:
    """Which objects of a sound BLF the damage of file bytes [lo, hi) leaves readable,
    by index (less the one before each damaged stretch), and the file offset of the
    container the damage starts in."""
    conts, objs = _layout(data)
    total = conts[-1][3] + conts[-1][4]
    ok = np.zeros(total, bool)
    first = conts[0][0]
    for off, size, method, start, length, payload in conts:
        if off <= lo:
            first = off
        if off + size <= lo or off >= hi:
            ok[start : start + length] = True
        elif method == 0:  # plain: every byte outside the damage, even with its header lost
            at = off + 32 + np.arange(length)
            ok[start : start + length] = (at < lo) | (at >= hi)
        elif lo > off + 32:  # zlib: what the bytes before the damage inflate to
            good = zlib.decompressobj().decompress(payload[: lo - off - 32])
            ok[start : start + len(good)] = True
    whole = [bool(ok[s:e].all()) for s, e in objs]
    kept = {i for i, w in enumerate(whole) if w and (i + 1 == len(whole) or whole[i + 1])}
    return kept, first


@pytest.mark.parametrize("where", ["middle", "container header"])
def test_blf_zeroed_in_the_middle(written, tmp_path, where):
    path, keys = written
    data = path.read_bytes()
    conts, _ = _layout(data)
    if where == "middle":
        lo = len(data) // 2
    else:  # the header of the third container and what follows it
        lo = conts[2][0] - 100
    damaged = tmp_path / "d.blf"
    damaged.write_bytes(_zeroed(data, lo))
    hi = lo + ZERO
    batch, ctx, _ = run(blf.read, damaged)
    got = set(_keys(batch))
    invented = got - set(keys)
    assert not invented, f"{len(invented)} frames invented, e.g. {sorted(invented)[:3]}"  # (a)
    kept, first = _kept_whole(data, lo, hi)
    lost = [i for i in sorted(kept) if keys[i] not in got]
    assert not lost, f"{len(lost)} frames lost outside the damage, e.g. {lost[:5]}"  # (b)
    assert len(got) >= len(kept) > len(keys) * 0.7
    assert any(first <= at < hi for at in _offsets(ctx.problems)), ctx.problems.shown  # (c)


def test_blf_overwritten_inside_a_compressed_container(tmp_path):
    """16 bytes overwritten in the middle of a zlib container: the container was dropped
    whole; what it inflates to before the damage is kept, nothing after it invented."""
    path = tmp_path / "z.blf"
    with can.BLFWriter(str(path), compression_level=6) as w:
        for m in _messages(12000):
            w.on_message_received(m)
    keys = [_key(m.timestamp, m.arbitration_id, m.data) for m in can.BLFReader(str(path))]
    data = path.read_bytes()
    conts, _ = _layout(data)
    for k in (1, 2, 3):  # three containers, one at a time, with different bytes
        off, size = conts[k][:2]
        lo = off + size // 2
        d = bytearray(data)
        d[lo : lo + 16] = random.Random(k).randbytes(16)
        damaged = tmp_path / f"o{k}.blf"
        damaged.write_bytes(bytes(d))
        batch, ctx, _ = run(blf.read, damaged)
        got = set(_keys(batch))
        invented = got - set(keys)
        assert not invented, f"container {k}: {len(invented)} frames invented"  # (a)
        kept, first = _kept_whole(data, lo, lo + 16)
        assert first == off
        lost = [i for i in sorted(kept) if keys[i] not in got]
        assert not lost, f"container {k}: {len(lost)} frames lost outside the damage"  # (b)
        # the damaged container's frames before the damage are among them (it was all lost)
        assert len(got) > len(keys) - conts[k][4] // 48 // 2 - 50
        assert off in _offsets(ctx.problems)  # (c)
        assert any("corrupt zlib data" in p.message for p in ctx.problems.shown)


def test_faults_sample_zeroed_in_the_middle(tmp_path):
    """The fuzz campaign's case: 1,709 frames out of a 933-frame log, 1,289 invented."""
    src = SAMPLES / "faults.blf"
    keys = {
        _key(m.timestamp, m.arbitration_id, m.data, m.is_error_frame)
        for m in can.BLFReader(str(src))
    }
    data = src.read_bytes()
    damaged = tmp_path / "faults.blf"
    damaged.write_bytes(_zeroed(data, len(data) // 2))
    batch, ctx, _ = run(blf.read, damaged)
    got = _keys(batch)
    assert set(got) <= keys and len(got) == len(set(got))
    assert len(got) > 400  # the frames inflated from before the damage (about 420)
    assert 144 in _offsets(ctx.problems)  # its one container


def test_library_and_cli_agree_on_the_damaged_sample(tmp_path):
    """The same through `open_log` (what `cananalyze.load` and the CLI read with)."""
    data = (SAMPLES / "faults.blf").read_bytes()
    damaged = tmp_path / "faults.blf"
    damaged.write_bytes(_zeroed(data, len(data) // 2))
    src = open_log(damaged)
    n = sum(len(b) for b in src.batches())
    batch, _, _ = run(blf.read, damaged)
    assert n == len(batch) and 0 < src.problems.count <= 5


def _damaged_blfs(path, tmp_path) -> list:
    """Copies of a BLF damaged in each of the ways above."""
    data = path.read_bytes()
    conts, _ = _layout(data)
    out = []
    for k, lo in enumerate([len(data) // 2, conts[2][0] - 100, conts[1][0] + conts[1][1] // 2]):
        d = _zeroed(data, lo) if k < 2 else bytearray(data)
        if k == 2:
            d[lo : lo + 16] = random.Random(k).randbytes(16)
        out.append(tmp_path / f"d{k}.blf")
        out[-1].write_bytes(bytes(d))
    return out


def test_both_walks_agree_on_the_damage(written, tmp_path):
    """The compiled walk and the Python walk: the same rows and problems (the walks and
    their checks are written twice)."""
    from tests.runtime.test_speedups import C, _same

    if C is None:
        pytest.skip("needs the compiled helper")
    for damaged in [*_damaged_blfs(written[0], tmp_path), SAMPLES / "faults.blf"]:
        _same(damaged, batch_size=3000)
    sample = tmp_path / "faults.blf"
    data = (SAMPLES / "faults.blf").read_bytes()
    sample.write_bytes(_zeroed(data, len(data) // 2))
    _same(sample)


# ----------------------------------------------------------------------- pcap, pcapng


def _scapy():
    return pytest.importorskip("scapy.all")


def _packets(n: int = 3000, seed: int = 5) -> list:
    """SocketCAN frames (link type 227) 1 ms apart: classic with 0-8 bytes, extended,
    CAN FD with 24 (scapy writes a record of 8 + the data length)."""
    from scapy.layers.can import CAN, CANFD

    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        data = rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8).tobytes()
        if i % 7 == 3:
            fd = rng.integers(0, 256, 24, dtype=np.uint8).tobytes()
            p = CANFD(identifier=0x123, length=24, fd_flags="bit_rate_switch", data=fd)
        elif i % 5 == 1:
            ident = int(rng.integers(0x800, 0x1FFFFFFF))
            p = CAN(identifier=ident, flags="extended", length=len(data), data=data)
        else:
            p = CAN(identifier=0x180 + i % 127, length=len(data), data=data)
        p.time = 1_700_000_000 + i * 0.001
        out.append(p)
    return out


@pytest.fixture(scope="module", params=["pcap", "pcapng"])
def capture(request, tmp_path_factory):
    """A capture scapy wrote, its frames as scapy reads them (keys, in file order), and
    its records or blocks: (offset, size, is a packet)."""
    scapy = _scapy()
    path = tmp_path_factory.mktemp("resync") / f"c.{request.param}"
    (scapy.wrpcap if request.param == "pcap" else scapy.wrpcapng)(str(path), _packets())
    keys = [_key(float(p.time), int(p.identifier), bytes(p.data)) for p in scapy.rdpcap(str(path))]
    data = path.read_bytes()
    units = []
    if request.param == "pcap":
        pos = 24
        while pos + 16 <= len(data):
            size = 16 + struct.unpack_from("<I", data, pos + 8)[0]
            units.append((pos, size, True))
            pos += size
    else:
        pos = 0
        while pos + 12 <= len(data):
            kind, size = struct.unpack_from("<II", data, pos)
            units.append((pos, size, kind == 6))
            pos += size
    assert sum(u[2] for u in units) == len(keys) == 3000
    return path, keys, units


def _read_capture(path):
    batch, ctx, _ = run(pcap.read, path)
    return set(_keys(batch)), ctx


def _whole_packets(units, lo: int, hi: int) -> set[int]:
    """The packets (by index) the damage of bytes [lo, hi) leaves whole, less the one
    just before the damage."""
    packets = [(pos, size) for pos, size, packet in units if packet]
    whole = [pos + size <= lo or pos >= hi for pos, size in packets]
    return {i for i, w in enumerate(whole) if w and (i + 1 == len(whole) or whole[i + 1])}


def test_capture_zeroed_in_the_middle(capture, tmp_path):
    path, keys, units = capture
    data = path.read_bytes()
    lo = len(data) // 2
    damaged = tmp_path / ("d" + path.suffix)
    damaged.write_bytes(_zeroed(data, lo))
    got, ctx = _read_capture(damaged)
    assert not got - set(keys)  # (a)
    kept = _whole_packets(units, lo, lo + ZERO)
    assert not [i for i in sorted(kept) if keys[i] not in got]  # (b)
    assert len(kept) > 2500
    start = max(pos for pos, _, _ in units if pos <= lo)
    assert ctx.problems.count == 1
    assert any(start - 100 <= at <= lo + ZERO for at in _offsets(ctx.problems))  # (c)


@pytest.mark.parametrize("claim", ["huge", "7 more", "4 less"])
def test_capture_length_corrupted(capture, tmp_path, claim):
    """One record's (pcap) or enhanced packet block's (pcapng) length corrupted: the
    rest of the file was lost (93 of 185, 467 of 933 frames read)."""
    path, keys, units = capture
    data = bytearray(path.read_bytes())
    packets = [(pos, size) for pos, size, packet in units if packet]
    k = len(packets) // 2
    pos, size = packets[k]
    at = pos + 8 if path.suffix == ".pcap" else pos + 4  # incl_len; the block's length
    old = struct.unpack_from("<I", data, at)[0]
    new = {"huge": 0x0FFFFFF0, "7 more": old + 7, "4 less": old - 4}[claim]
    if path.suffix == ".pcapng" and claim == "7 more":
        new = old + 8  # a multiple of 4: the trailing length tells
    struct.pack_into("<I", data, at, new)
    damaged = tmp_path / ("l" + path.suffix)
    damaged.write_bytes(bytes(data))
    got, ctx = _read_capture(damaged)
    assert not got - set(keys)  # (a)
    lost = [i for i in range(len(keys)) if keys[i] not in got]
    assert set(lost) <= {k, k + 1}, lost  # (b): the damaged one (and the one it overlaps)
    assert ctx.problems.count == 1, ctx.problems.shown
    assert any(pos <= at <= pos + 2 * size for at in _offsets(ctx.problems))  # (c)
    assert "skipped" in ctx.problems.shown[0].message


@pytest.mark.parametrize("chunk", [61, 1000, 4099])
def test_capture_read_in_small_chunks(capture, tmp_path, monkeypatch, chunk):
    """Damage at any place relative to the reader's chunks (and its search's windows):
    the same frames and problems as read in one go (a record or block judged with the
    bytes after it, a search for the next one going on in the next chunk)."""
    path, _, units = capture
    data = path.read_bytes()
    packets = [(pos, size) for pos, size, packet in units if packet]
    pos, size = packets[len(packets) // 3]
    d = bytearray(_zeroed(data, len(data) // 2, 700))
    at = pos + 8 if path.suffix == ".pcap" else pos + 4
    struct.pack_into("<I", d, at, 0x0FFFFFF0)
    damaged = tmp_path / ("k" + path.suffix)
    damaged.write_bytes(bytes(d))
    ref, ref_ctx, _ = run(pcap.read, damaged)
    monkeypatch.setattr(pcap, "CHUNK", chunk)
    monkeypatch.setattr(pcap, "SCAN_WINDOW", chunk // 2 + 12)
    got, ctx, _ = run(pcap.read, damaged)
    assert _keys(got) == _keys(ref) and len(ref) > 2800
    assert ctx.problems.shown == ref_ctx.problems.shown and ref_ctx.problems.count == 2
