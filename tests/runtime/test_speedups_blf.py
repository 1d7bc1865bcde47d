"""The compiled BLF object walk (`_speedups.blf_records`) gives the Python walk's results.

Every file is read with the extension and with `speedups.C = None` and compared
column by column with problems, record numbers and strict-mode errors
(`test_speedups._same`): every BLF in the real data, the samples, files python-can
writes (CAN FD, error frames, remote frames, several channels, plain and zlib
containers), and damaged files (the hostile-input cases, garbage and bad lengths
inside containers, seeded random byte damage). The compiled run must not have
handed the buffer to the Python walk, except where it says it does (more problems
in one buffer than it keeps).
"""

from __future__ import annotations

import random
import struct
import zlib
from pathlib import Path

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from readers_util import run

from cananalyze.formats.logs import blf
from cananalyze.runtime import speedups
from tests.conftest import REAL, real_file
from tests.runtime.test_speedups import SAMPLES, _read, _same

C = speedups.C
pytestmark = pytest.mark.skipif(C is None, reason=f"needs the compiled helper: {speedups.status()}")


@pytest.fixture
def python_walks(monkeypatch) -> list[int]:
    """How many buffers the Python walk parsed while the compiled helper was in use."""
    calls: list[int] = []
    real = blf._Records._parse_py

    def counted(self, buf, *args):
        if speedups.C is not None:
            calls.append(len(buf))
        return real(self, buf, *args)

    monkeypatch.setattr(blf._Records, "_parse_py", counted)
    return calls


def _real_blfs() -> list[str]:
    found = sorted(str(p.relative_to(REAL)) for p in REAL.rglob("*.blf")) if REAL.exists() else []
    return found or ["hardbyte__python-can/test_CanMessage.blf"]  # skips when absent


@pytest.mark.parametrize("name", _real_blfs())
def test_real_blfs(name: str, python_walks) -> None:
    assert _same(real_file(name), batch_size=7) > 0
    assert python_walks == []


@pytest.mark.parametrize("name", ["demo.blf", "faults.blf", "commissioning.blf"])
def test_samples(name: str, python_walks) -> None:
    assert _same(SAMPLES / name) > 0
    assert python_walks == []


def _messages(n: int, seed: int) -> list[can.Message]:
    """Classic, extended, remote, FD (up to 64 bytes, BRS, ESI) and error frames on 3 channels."""
    rnd = random.Random(seed)
    out = []
    for i in range(n):
        kw = {"timestamp": 1700000000.0 + i * 0.0007, "channel": rnd.randrange(3)}
        r = rnd.random()
        if r < 0.04:
            out.append(can.Message(is_error_frame=True, **kw))
        elif r < 0.14:
            size = rnd.choice([0, 3, 8, 12, 20, 48, 64])
            out.append(
                can.Message(
                    arbitration_id=rnd.randrange(0x800),
                    is_fd=True,
                    bitrate_switch=rnd.random() < 0.5,
                    error_state_indicator=rnd.random() < 0.2,
                    data=bytes(rnd.randrange(256) for _ in range(size)),
                    is_rx=rnd.random() < 0.7,
                    **kw,
                )
            )
        else:
            ext = rnd.random() < 0.2
            remote = rnd.random() < 0.05
            out.append(
                can.Message(
                    arbitration_id=rnd.randrange(0x20000000 if ext else 0x800),
                    is_extended_id=ext,
                    is_remote_frame=remote,
                    dlc=rnd.randrange(9) if remote else None,
                    data=None
                    if remote
                    else bytes(rnd.randrange(256) for _ in range(rnd.randrange(9))),
                    is_rx=rnd.random() < 0.8,
                    **kw,
                )
            )
    return out


@pytest.fixture(scope="module", params=[0, 6], ids=["plain", "zlib"])
def written(request, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("blf") / f"mixed{request.param}.blf"
    with can.BLFWriter(str(path), compression_level=request.param) as w:
        for m in _messages(15000, seed=5):  # several containers; records straddle them
            w.on_message_received(m)
    return path


def test_written_by_python_can(written: Path, python_walks) -> None:
    assert _same(written, batch_size=4000) == 15000
    assert python_walks == []
    batch, _, _ = run(blf.read, written, batch_size=20000)
    kinds = {int(k) for k in np.unique(batch.flags)}
    assert len(kinds) >= 6 and len(batch.channels) == 3 and batch.long_data  # every kind there


def test_buffers_of_one_container(written: Path, monkeypatch, python_walks) -> None:
    """Each container parsed alone: every straddling record joined from two buffers."""
    monkeypatch.setattr(blf, "PARSE_BYTES", 1)
    assert _same(written, batch_size=999) == 15000
    assert python_walks == []


@pytest.mark.parametrize(
    ("batch_size", "parse_bytes"), [(20000, None), (6000, 1), (100_000, 1), (4000, 1 << 14)]
)
def test_rows_written_into_the_batch_being_filled(
    written: Path, monkeypatch, python_walks, batch_size: int, parse_bytes: int | None
) -> None:
    """The compiled walk writes a buffer's rows straight into the batch being filled when
    they fit, else through its reused buffers: either way, and mixed across the ends of
    batches, the Python walk's batches (exactly batch_size rows, long CAN FD payloads at
    their rows, the channel table)."""
    if parse_bytes is not None:
        monkeypatch.setattr(blf, "PARSE_BYTES", parse_bytes)
    direct: list[int] = []
    commit = blf._Cutter.commit

    def counted(self, n, channels, long):
        direct.append(n)
        return commit(self, n, channels, long)

    monkeypatch.setattr(blf._Cutter, "commit", counted)
    assert _same(written, batch_size=batch_size) == 15000
    assert python_walks == [] and sum(direct) > 0
    batch, _, batches = run(blf.read, written, batch_size=batch_size)
    sizes = [len(b) for b in batches]
    assert sizes == [batch_size] * (15000 // batch_size) + (
        [15000 % batch_size] if 15000 % batch_size else []
    )
    assert batch.long_data and len(batch.channels) == 3


def _parts(path: Path) -> tuple[bytes, bytes]:
    """A BLF's file header and the inflated bytes of all its containers."""
    data = path.read_bytes()
    hs = struct.unpack_from("<I", data, 4)[0]
    pos, inner = hs, bytearray()
    while pos + 16 <= len(data):
        size = struct.unpack_from("<I", data, pos + 8)[0]
        method = struct.unpack_from("<H", data, pos + 16)[0]
        body = data[pos + 32 : pos + size]
        inner += zlib.decompress(body) if method == 2 else body
        pos += size + size % 4
    return data[:hs], bytes(inner)


def _file(head: bytes, inner: bytes, step: int = 1 << 17) -> bytes:
    """A BLF of plain containers of `step` bytes holding `inner` (the file size set)."""
    out = bytearray(head)
    for k in range(0, len(inner), step):
        part = inner[k : k + step]
        size = 32 + len(part)
        out += b"LOBJ" + struct.pack("<HHLL", 16, 1, size, 10)
        out += struct.pack("<H6xL4x", 0, len(part)) + part + bytes(size % 4)
    struct.pack_into("<Q", out, 16, len(out))
    return bytes(out)


@pytest.fixture(scope="module")
def inner(written) -> tuple[bytes, bytes]:
    return _parts(written)


def _objects(data: bytes) -> list[int]:
    """Offsets of the objects in inflated container bytes (padded to 4)."""
    pos, out = 0, []
    while pos + 16 <= len(data):
        out.append(pos)
        size = struct.unpack_from("<I", data, pos + 8)[0]
        pos += size + size % 4
    return out


def _damaged(inner: bytes, at: list[int], how) -> bytes:
    data = bytearray(inner)
    for k in reversed(at):
        how(data, k)
    return bytes(data)


DAMAGE = {
    # garbage between records: resynchronised on the next LOBJ, reported by the walk
    "garbage": lambda d, k: d.__setitem__(slice(k, k), b"JUNK" * 3),
    # an object size below 16 or beyond MAX_INNER
    "bad size": lambda d, k: struct.pack_into("<I", d, k + 8, 3 if k % 2 else 60 << 20),
    # an unknown header version
    "version": lambda d, k: struct.pack_into("<H", d, k + 6, 7),
    # a header size leaving no room for the body
    "header size": lambda d, k: struct.pack_into("<H", d, k + 4, 0xFFF0),
    # a header shorter than the object header's time
    "short header": lambda d, k: struct.pack_into("<H", d, k + 4, 8),
    # a lost signature
    "signature": lambda d, k: d.__setitem__(slice(k, k + 4), b"XOBJ"),
}


@pytest.mark.parametrize("kind", list(DAMAGE))
def test_damaged_records(tmp_path: Path, inner, kind: str, python_walks) -> None:
    head, data = inner
    objs = _objects(data)
    at = objs[5 : len(objs) : 997][:20]  # a few per buffer: the compiled walk reports them
    path = tmp_path / "d.blf"
    path.write_bytes(_file(head, _damaged(data, at, DAMAGE[kind])))
    n = _same(path, batch_size=3000)
    assert 0 < n < 15000 or kind == "garbage"
    assert python_walks == []
    _, problems, _ = _read(path, pure=False)
    assert problems.count >= len(at)


def test_many_problems_go_to_the_python_walk(tmp_path: Path, inner, python_walks) -> None:
    """More problems in one buffer than the compiled walk keeps: the Python walk takes it."""
    head, data = inner
    objs = _objects(data)
    at = objs[10:400:3]  # 130 damaged records in the first buffer
    path = tmp_path / "many.blf"
    path.write_bytes(_file(head, _damaged(data, at, DAMAGE["version"])))
    assert _same(path) == 15000 - len(at)
    assert python_walks  # declined, and the results are still the same


@pytest.mark.parametrize("seed", range(12))
def test_random_byte_damage(tmp_path: Path, inner, seed: int, python_walks) -> None:
    head, data = inner
    rnd = random.Random(seed)
    d = bytearray(data[: 40000 + rnd.randrange(40000)])
    for _ in range(rnd.choice([1, 5, 40])):
        k = rnd.randrange(len(d))
        d[k : k + rnd.randrange(1, 5)] = bytes(rnd.randrange(256) for _ in range(rnd.randrange(5)))
    path = tmp_path / "r.blf"
    path.write_bytes(_file(head, bytes(d), step=rnd.choice([97, 4096, 1 << 17])))
    _same(path, batch_size=500)


@pytest.mark.parametrize("case", ["huge header", "garbage between containers", "inner 60 MiB"])
def test_hostile_input_files(tmp_path: Path, case: str, python_walks) -> None:
    """The damaged BLFs of tests/pipeline/test_robust_hostile.py, read both ways."""
    from tests.pipeline.test_robust_hostile import _blf, _blf_parts

    a, b = tmp_path / "a.blf", tmp_path / "b.blf"
    _blf(a, 200)
    _blf(b, 200, t0=10.0)
    head, first = _blf_parts(a)
    p = tmp_path / "h.blf"
    if case == "huge header":
        d = bytearray(a.read_bytes())
        d[4:8] = struct.pack("<I", 0x7FFFFFFF)
        p.write_bytes(bytes(d))
    elif case == "garbage between containers":
        _, second = _blf_parts(b)
        p.write_bytes(head + b"".join(first) + b"\x13\x37" * 501 + b"".join(second))
    else:
        _, data = _parts(a)
        bad = data[:8] + struct.pack("<I", 60 << 20) + data[12:]
        p.write_bytes(_file(head, bad, step=len(bad) // 2 + 1))
    assert _same(p) in (199, 200, 400)
    assert python_walks == []


# object headers the fuzzer splices in: sizes, versions, header sizes and kinds near the limits
_HEADERS = st.builds(
    lambda hsize, hver, size, kind: b"LOBJ" + struct.pack("<HHLL", hsize, hver, size, kind),
    st.sampled_from([0, 16, 31, 32, 40, 48, 0xFFFF]),
    st.sampled_from([0, 1, 2, 3]),
    st.sampled_from([0, 15, 16, 32, 47, 48, 60, 72, 100, 116, 124, 1 << 20, (1 << 20) + 1]),
    st.sampled_from([1, 10, 73, 86, 100, 101, 5]),
)


@pytest.mark.slow  # 150 fuzzed containers per mode
@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    pieces=st.lists(
        _HEADERS | st.binary(max_size=80) | st.sampled_from([b"LOBJ", b"\0" * 4]), max_size=30
    ),
    cut=st.integers(0, 3),
)
def test_fuzzed_objects(tmp_path: Path, inner, pieces: list[bytes], cut: int) -> None:
    """Valid records around fuzzed object headers and bytes, in one or several containers."""
    head, data = inner
    body = data[:480] + b"".join(pieces) + data[480:960]
    path = tmp_path / "f.blf"
    path.write_bytes(_file(head, body, step=[1 << 17, 100, 37, 7][cut]))
    _same(path, batch_size=5)
