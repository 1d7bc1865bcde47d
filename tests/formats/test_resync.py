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
from cananalyze.formats.logs import blf
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
