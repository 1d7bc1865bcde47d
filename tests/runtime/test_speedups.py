"""The compiled helper (`_speedups.c`) gives exactly the pure-Python readers' results.

Every log is read twice, with the extension and with `speedups.C = None` (what
`CANANALYZE_PURE=1` or a machine without a compiler gives), and every batch is
compared column by column, with the interface names, problems, line numbers and
strict-mode errors: real candump and ASC logs, the samples, generated traffic,
seeded random lines around the usual layouts, and hypothesis-fuzzed bytes.
Skipped when the extension is not built or CANANALYZE_PURE is set (nothing to compare).
"""

from __future__ import annotations

import importlib.util
import os
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cananalyze.core.errors import InputError, ProblemLog
from cananalyze.core.frames import FLAG_RTR, FrameBatch
from cananalyze.formats.logs import asc, candump
from cananalyze.formats.source import open_log
from cananalyze.runtime import speedups
from tests.conftest import real_file

C = speedups.C
pytestmark = pytest.mark.skipif(C is None, reason=f"needs the compiled helper: {speedups.status()}")
ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "samples"
COLUMNS = ("t", "can_id", "flags", "dlc", "data", "channel", "line")


def _read(path: Path, pure: bool, strict: bool = False, batch_size: int | None = None):
    """(batches, problems, context) or the strict-mode error text."""
    saved = speedups.C
    speedups.C = None if pure else C
    try:
        problems = ProblemLog()
        kw = {"batch_size": batch_size} if batch_size else {}
        src = open_log(path, strict=strict, problems=problems, **kw)
        try:
            batches = list(src.batches())
        except InputError as exc:
            return str(exc)
        return batches, problems, src.ctx
    finally:
        speedups.C = saved


def _same(path: Path, batch_size: int | None = None) -> int:
    """Assert both paths agree on `path`; the number of frames read."""
    ref = _read(path, pure=True, batch_size=batch_size)
    got = _read(path, pure=False, batch_size=batch_size)
    if isinstance(ref, str) or isinstance(got, str):  # nothing readable: the same failure
        assert got == ref
        return 0
    ref_b, ref_p, ref_ctx = ref
    got_b, got_p, got_ctx = got
    assert len(got_b) == len(ref_b)
    for g, r in zip(got_b, ref_b, strict=True):
        assert isinstance(g, FrameBatch)
        for name in COLUMNS:
            a, b = getattr(g, name), getattr(r, name)
            assert a.dtype == b.dtype, name
            assert np.array_equal(a, b), (name, path)
        assert g.channels == r.channels
        assert g.long_data == r.long_data
    assert got_p.count == ref_p.count
    assert [str(p) for p in got_p.shown] == [str(p) for p in ref_p.shown]
    for attr in ("frames", "absolute_time", "start_time", "format", "extras"):
        assert getattr(got_ctx, attr) == getattr(ref_ctx, attr), attr
    rs, gs = _read(path, pure=True, strict=True), _read(path, pure=False, strict=True)
    if isinstance(rs, str) or isinstance(gs, str):
        assert gs == rs  # the same first problem stops both
    else:
        assert [len(b) for b in gs[0]] == [len(b) for b in rs[0]]
    return sum(len(b) for b in ref_b)


REAL = [
    "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log",
    "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log",
    "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test3.log",
    "collin80__SavvyCAN/candump.log",
    "RoboTrainerAID__za_experimental/candump.log",
    "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
    "jclinton830__canopen_test/candump.txt",
    "SeonilChoi__CANOPEN-SDK/log.txt",
    "SeonilChoi__CANOPEN-SDK/log2.txt",
    "hardbyte__python-can/test_CanErrorFrames.asc",
    "hardbyte__python-can/test_CanFdMessage64.asc",
    "hardbyte__python-can/test_CanRemoteMessage.asc",
    "hardbyte__python-can/test_CanFdMessage.asc",
    "hardbyte__python-can/single_frame.asc",
    "hardbyte__python-can/issue_1256.asc",
    "hardbyte__python-can/logfile.asc",
    "hardbyte__python-can/single_frame_us_locale.asc",
    "hardbyte__python-can/test_CanMessage.asc",
    "hardbyte__python-can/issue_1299.asc",
    "hardbyte__python-can/test_CanFdRemoteMessage.asc",
    "hardbyte__python-can/logfile_errorframes.asc",
]


@pytest.mark.parametrize("name", REAL)
def test_real_logs(name: str) -> None:
    _same(real_file(name))


@pytest.mark.parametrize(
    "name",
    ["demo.log", "faults.log", "commissioning.log", "demo.asc", "faults.asc", "commissioning.asc"],
)
def test_samples(name: str) -> None:
    assert _same(SAMPLES / name) > 0


def _generate():
    spec = importlib.util.spec_from_file_location("bench_generate", ROOT / "benchmarks/generate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("suffix", [".log", ".asc"])
def test_generated_traffic_across_chunks(tmp_path: Path, monkeypatch, suffix: str) -> None:
    from cananalyze.formats.logfile import write_log

    gen = _generate()
    path = tmp_path / f"bench{suffix}"
    write_log(gen.generate(20000, seed=3), path)
    monkeypatch.setattr(candump, "CHUNK", 1 << 14)  # many chunks: carried partial lines
    monkeypatch.setattr(asc, "CHUNK", 1 << 14)
    assert _same(path, batch_size=3000) == 20000


_HEX = "0123456789abcdefABCDEF"


def _line(rng: random.Random) -> str:
    """A log-file line around the usual layout: other widths, interfaces, ids (3-digit
    ones above 7FF too), data lengths, direction flags, RTR, CAN FD, stray bytes."""
    ni = 10 if rng.random() < 0.8 else rng.choice([1, 3, 9, 11, 16])
    nf = 6 if rng.random() < 0.8 else rng.choice([3, 9, 1])
    t = (
        "".join(rng.choice("0123456789") for _ in range(ni))
        + "."
        + "".join(rng.choice("0123456789") for _ in range(nf))
    )
    ch = (
        "can0"
        if rng.random() < 0.8
        else rng.choice(["can1", "vcan10", "a-very-long-interface-name0"])
    )
    ident = "".join(rng.choice(_HEX) for _ in range(rng.choice([3, 3, 3, 8, 8, 2, 5])))
    if rng.random() < 0.05:
        ident = "2" + ident[1:]  # 29-bit with the error flag when 8 digits
    n = rng.choice([0, 1, 2, 4, 7, 8, 8, 8, 9])
    data = "".join(rng.choice(_HEX) for _ in range(2 * n))
    kind = rng.random()
    if kind < 0.04:
        data = "R" + rng.choice(["", "3", "8", "9"])
    elif kind < 0.07:
        data = "#" + rng.choice("0123") + data
    line = f"({t}) {ch} {ident}#{data}"
    if rng.random() < 0.3:
        line += rng.choice([" R", " T", " X", " ", "  T"])
    if rng.random() < 0.08:  # one stray byte anywhere
        i = rng.randrange(len(line) + 1)
        line = line[:i] + rng.choice(" #().xZ\t0") + line[i + 1 :]
    return line


def _candump_line(rng: random.Random) -> str:
    line = _line(rng)
    r = rng.random()
    if r < 0.03:  # the screen format and other variants the line parser reads
        line = f"  can{rng.randrange(3)}  {rng.choice(['181', '18FF00A1', '7E5'])}   [2]  01 02"
    elif r < 0.05:
        line = line.replace(".", "", 1)  # no fraction
    elif r < 0.07:
        line = line[: rng.randrange(len(line) + 1)]  # cut anywhere
    elif r < 0.08:
        line = " " + line
    elif r < 0.09:
        line = line.replace("can0", rng.choice(["", "can 0", "vcan\x00", "é"]), 1)
    elif r < 0.10:
        line += "\r"
    elif r < 0.11:
        line = ""
    elif r < 0.12:
        line = line.replace("#", "#r", 1)
    return line


def _asc_line(rng: random.Random) -> str:
    t = f"{rng.randrange(10 ** rng.choice([1, 3, 5]))}.{rng.randrange(10**6):06d}"
    if rng.random() < 0.05:
        t = rng.choice(["12", "12.", "1.5e3", ".5", "1" * 20 + ".0"])
    ch = rng.choice(["1", "1", "2", "12", "123", "1234", "x"])
    ident = "".join(rng.choice(_HEX) for _ in range(rng.choice([1, 2, 3, 3, 8])))
    if rng.random() < 0.2:
        ident += rng.choice("xX")
    direction = rng.choice(["Rx", "Tx", "Rx", "rx", "TX"])
    kind = rng.choice(["d", "d", "d", "d", "r", "D"])
    n = rng.choice([0, 1, 2, 8, 8, 8, 9, 15])
    code = format(n, "x") if rng.random() < 0.9 else rng.choice(["10", "g", ""])
    data = " ".join(
        "".join(rng.choice(_HEX) for _ in range(rng.choice([2, 2, 2, 2, 2, 1, 3])))
        for _ in range(min(n, 8) - (rng.random() < 0.05))
    )
    tail = rng.choice(["", "", "  Length = 272000 BitCount = 140 ID = 384", "\t", " \r"])
    line = f" {t} {ch}  {ident}             {direction}   {kind} {code} {data}{tail}"
    r = rng.random()
    if r < 0.03:
        line = line[: rng.randrange(len(line) + 1)]
    elif r < 0.05:
        line = rng.choice(
            [
                "   0.000000 Start of measurement",
                "   1.000000 1  ErrorFrame",
                "   2.000000 CANFD   1 Rx        123  1 0 8  8 01 02 03 04 05 06 07 08",
                "// comment",
                "Begin Triggerblock Thu Jan 01 00:00:01.0 2026",
                "",
                "base hex  timestamps absolute",
                " BaSE hex  timestamps absolute",
                "\tbase dec  timestamps absolute",
                "base hex timestamps relative",
                "basehex",
                "Base",
            ]
        )
    elif r < 0.07:
        i = rng.randrange(len(line) + 1)
        line = line[:i] + rng.choice(["\x00", "\x0b", "\xa0", "\x7f", "  ", "."]) + line[i:]
    return line


HEADER = "date Thu Jan 01 00:00:00.0 2026\nbase hex  timestamps absolute\ninternal events logged\n"


@pytest.mark.parametrize("seed", range(4))
def test_random_candump_lines(tmp_path: Path, seed: int) -> None:
    rng = random.Random(seed)
    lines = [_candump_line(rng) for _ in range(5000)]
    path = tmp_path / "x.log"
    path.write_bytes(("\n".join(lines) + ("\n" if seed % 2 else "")).encode("utf-8"))
    _same(path, batch_size=777)


@pytest.mark.parametrize("seed", range(4))
def test_random_asc_lines(tmp_path: Path, seed: int) -> None:
    rng = random.Random(seed)
    lines = [_asc_line(rng) for _ in range(5000)]
    path = tmp_path / "x.asc"
    path.write_bytes((HEADER + "\n".join(lines) + "\n").encode("latin-1"))
    _same(path, batch_size=777)


_ALPHABET = st.sampled_from(
    list(b"()0123456789.#RTxXrd abcdefABCDEF\t\r\n\x00\xff-can") + [ord(" ")]
)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    head=st.sampled_from([b"(1767225600.000123) can0 181#0102\n", HEADER.encode(), b""]),
    body=st.lists(st.integers(0, 255) | _ALPHABET, max_size=400).map(bytes),
    suffix=st.sampled_from([".log", ".asc"]),
)
def test_fuzzed_bytes(tmp_path: Path, head: bytes, body: bytes, suffix: str) -> None:
    path = tmp_path / f"f{suffix}"
    path.write_bytes(head + body)
    try:
        _read(path, pure=True)
    except InputError:  # not a log at all: both paths fail the same way in open_log
        return
    _same(path, batch_size=5)


def test_hex_payload_column() -> None:
    import pyarrow as pa

    from cananalyze.core.columns import hexcols

    rng = np.random.default_rng(1)
    n = 5000
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    dlc = rng.integers(0, 16, n).astype(np.uint8)
    flags = rng.integers(0, 256, n).astype(np.uint8)
    got = hexcols.hex_payload_buffers(data, dlc, flags)
    saved = speedups.C
    speedups.C = None
    try:
        ref = hexcols.hex_payload_buffers(data, dlc, flags)
    finally:
        speedups.C = saved
    assert bytes(got[0]) == bytes(ref[0]) and np.array_equal(got[1], ref[1])
    arr = pa.Array.from_buffers(pa.string(), n, [None, pa.py_buffer(got[1]), pa.py_buffer(got[0])])
    want = [
        "" if f & FLAG_RTR else bytes(d[: min(k, 8)]).hex()
        for d, k, f in zip(data, dlc, flags, strict=True)
    ]
    assert arr.to_pylist() == want


@pytest.mark.parametrize("name", ["demo.log", "demo.asc"])
def test_cli_pure_and_compiled_agree(name: str) -> None:
    """The whole program, in a subprocess: the same output with CANANALYZE_PURE=1."""
    cmd = [sys.executable, "-m", "cananalyze", "decode", str(SAMPLES / name)]
    env = dict(os.environ, CANANALYZE_PURE="")
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, check=True).stdout
    env["CANANALYZE_PURE"] = "1"
    pure = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, check=True).stdout
    assert out == pure and len(out) > 1000


def test_candump_chunk_of_short_lines(tmp_path: Path) -> None:
    """Lines shorter than the split's room estimate (blank lines, bare frames): the counted path."""
    frame = b"(1.0) c 001#\n"  # 13 bytes, below the 24-byte average the split assumes
    body = (b"\n" * 50 + frame * 200) * 20
    path = tmp_path / "short.log"
    path.write_bytes(body)
    assert _same(path) == 4000


@pytest.mark.parametrize("seed", range(4))
def test_compact_rows_matches_numpy(seed: int) -> None:
    """The text writer's compaction: the same bytes and row ends as the numpy passes."""
    from cananalyze.core.columns import bytecols

    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 3000))
    parts = []
    for _ in range(int(rng.integers(1, 12))):
        w = int(rng.integers(0, 40))
        m = rng.integers(0, 256, (n, w), dtype=np.uint8)
        m[rng.random((n, w)) < 0.3] = bytecols.PAD  # padding anywhere, not only at row ends
        parts.append(m)
    parts.append(rng.integers(0, 256, (n, 24), dtype=np.uint8)[:, :23])  # a strided view
    parts.insert(1, bytecols.repeat(b'{"k":\0x', n))  # the same on every row, a pad inside
    parts.append(bytecols.repeat(b"}", n))
    for with_ends in (True, False):
        got, got_ends = bytecols.compact(parts, n, with_ends)
        saved = speedups.C
        speedups.C = None
        try:
            ref, ref_ends = bytecols.compact(parts, n, with_ends)
        finally:
            speedups.C = saved
        assert got == ref
        assert (got_ends is None) == (ref_ends is None) == (not with_ends)
        if with_ends:
            assert got_ends.tolist() == ref_ends.tolist()


def test_compact_rows_checks_its_buffers() -> None:
    parts = [np.zeros((10, 4), np.uint8)]
    with pytest.raises(ValueError, match="part 0"):
        C.compact_rows(parts, [4], 11, 0, None)  # fewer rows than n
    with pytest.raises(ValueError, match="ends"):
        C.compact_rows(parts, [4], 10, 0, np.empty(9, np.int64))
    with pytest.raises(ValueError):
        C.compact_rows(parts, [4, 4], 10, 0, None)  # a width per part


@pytest.mark.parametrize("seed", range(4))
def test_gather_rows_matches_numpy_layout(seed: int) -> None:
    """The MCAP chunk layout: records from many texts, merged and in any row order, are
    the same bytes with gather_rows as with the numpy gather."""
    from cananalyze.core.columns.json_text import Texts
    from cananalyze.formats.mcap_bulk import BulkMcapWriter, _Rows

    rng = np.random.default_rng(seed)
    texts = []
    for _ in range(int(rng.integers(1, 70))):  # more sources than compact_rows' 64 parts
        items = [rng.bytes(int(rng.integers(0, 90))) for _ in range(int(rng.integers(0, 60)))]
        texts.append(Texts.from_list(items))
    payload = _Rows(texts)
    if payload.n == 0:
        return
    rows = rng.permutation(payload.n)
    channel = rng.integers(1, 9, payload.n).astype(np.uint16)
    log_time = np.sort(rng.integers(0, 10**12, payload.n)).astype(np.uint64)
    w = BulkMcapWriter.__new__(BulkMcapWriter)
    w._buffers = {}
    w._chunk_bytes = 4096
    got, got_starts = w._layout(channel, log_time, payload, rows)
    saved = speedups.C
    speedups.C = None
    try:
        ref, ref_starts = w._layout(channel, log_time, payload, rows)
    finally:
        speedups.C = saved
    assert got == ref and got_starts.tolist() == ref_starts.tolist()


def test_gather_rows_checks_its_ranges() -> None:
    heads = np.zeros((2, 3), np.uint8)
    src = [np.frombuffer(b"abcdef", np.uint8)]
    part = np.zeros(2, np.int32)
    ok = C.gather_rows(heads, 3, src, part, np.array([0, 4], np.int64), np.array([2, 2], np.int64))
    assert ok == b"\0\0\0ab\0\0\0ef"
    with pytest.raises(ValueError, match="record 1"):
        C.gather_rows(heads, 3, src, part, np.array([0, 5], np.int64), np.array([2, 2], np.int64))
    with pytest.raises(ValueError, match="record 0"):
        C.gather_rows(
            heads, 3, src, np.array([1, 0], np.int32), np.zeros(2, np.int64), np.ones(2, np.int64)
        )
    with pytest.raises(ValueError, match="heads"):
        C.gather_rows(heads[:1], 3, src, part, np.zeros(2, np.int64), np.ones(2, np.int64))


def _frames(rng, n: int) -> FrameBatch:
    z = np.zeros(n)
    return FrameBatch(
        t=z,
        can_id=z.astype(np.uint32),
        flags=rng.integers(0, 256, n).astype(np.uint8),
        dlc=rng.integers(0, 16, n).astype(np.uint8),
        data=rng.integers(0, 256, (n, 8), dtype=np.uint8),
        channel=z.astype(np.int32),
        line=z.astype(np.int64),
    )


@pytest.mark.parametrize("seed", range(6))
def test_payload_pack_matches_numpy(seed: int) -> None:
    """The frames table's binary column: the C pass and the numpy path give the same
    buffers and values (RTR rows and every dlc, 0-15; empty and one-row batches)."""
    from cananalyze.core.columns import payloads

    rng = np.random.default_rng(seed)
    fb = _frames(rng, [0, 1, 7, 5000, 100_000, 3][seed])
    got = payloads.payload_bytes(fb)
    saved = speedups.C
    speedups.C = None
    try:
        ref = payloads.payload_bytes(fb)
    finally:
        speedups.C = saved
    assert got.equals(ref)
    assert got.buffers()[1] == ref.buffers()[1]
    want = [
        b"" if f & FLAG_RTR else bytes(d[: min(k, 8)])
        for d, k, f in zip(fb.data, fb.dlc, fb.flags, strict=True)
    ]
    assert got.to_pylist() == want


def test_payload_pack_checks_its_buffers() -> None:
    data = np.zeros((4, 8), np.uint8)
    dlc = np.full(4, 8, np.uint8)
    with pytest.raises(ValueError, match="values"):
        C.payload_pack(data, dlc, dlc, FLAG_RTR, np.empty(31, np.uint8), np.empty(5, np.int32))
    with pytest.raises(ValueError, match="offsets"):
        C.payload_pack(data, dlc, dlc, FLAG_RTR, np.empty(32, np.uint8), np.empty(4, np.int32))


def _frame_docs(fb, service, node):
    """frame_payloads with the helper, then the numpy path: (bytes, offsets) each."""
    from cananalyze.formats.mcap_frames import frame_payloads

    got = frame_payloads(fb, service, node)
    saved = speedups.C
    speedups.C = None
    try:
        ref = frame_payloads(fb, service, node)
    finally:
        speedups.C = saved
    return (bytes(got.data), got.offsets.tolist()), (bytes(ref.data), ref.offsets.tolist())


@pytest.mark.parametrize("seed", range(6))
def test_frame_json_is_the_numpy_documents(seed: int) -> None:
    """/can/frames documents: any identifier, dlc, flags (RTR: no data), service, node
    (-1: none), channel label (JSON-escaped), CAN FD payloads past 8 bytes."""
    import json

    from cananalyze.protocol.services import SERVICE_NAMES

    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 3000))
    labels = ("can0", "CAN 1", 'bus "2"', "vcan\u00e9")[: int(rng.integers(1, 5))]
    fb = FrameBatch.allocate(n, labels)
    fb.can_id[:] = rng.integers(0, 1 << 29, n)
    fb.dlc[:] = rng.integers(0, 9, n)
    fb.flags[:] = rng.integers(0, 128, n)
    fb.data[:] = rng.integers(0, 256, (n, 8))
    fb.channel[:] = rng.integers(0, len(labels), n)
    for i in rng.choice(n, min(n, 5), replace=False).tolist() if n else []:
        fb.long_data[i] = rng.bytes(int(rng.integers(9, 65)))
        fb.dlc[i] = len(fb.long_data[i])
    service = rng.integers(0, len(SERVICE_NAMES), n).astype(np.uint8)
    node = rng.integers(-1, 128, n).astype(np.int16)
    got, ref = _frame_docs(fb, service, node)
    assert got == ref
    docs = [json.loads(got[0][a:b]) for a, b in zip(got[1], got[1][1:], strict=False)]
    assert len(docs) == n
    for i, d in enumerate(docs):
        assert d["channel"] == labels[fb.channel[i]] and d["node"] == node[i]
        assert d["data"] == ("" if fb.flags[i] & FLAG_RTR else fb.payload(i).hex())


@pytest.mark.parametrize("name", ["demo.log", "faults.asc"])
def test_frame_json_on_the_samples(name: str) -> None:
    import cananalyze

    c = cananalyze.load(SAMPLES / name)
    got, ref = _frame_docs(c.batch, c.service, c.node)
    assert got == ref and len(got[1]) == len(c.batch) + 1


def test_frame_json_checks_its_tables() -> None:
    fb = FrameBatch.allocate(3, ("can0",))
    fb.channel[1] = 1  # no label for channel 1
    args = (fb.channel, fb.can_id, fb.dlc, fb.data, np.zeros(3, np.int64), fb.flags)
    with pytest.raises(ValueError, match="row 1"):
        C.frame_json([b'"can0"'], [b'"x"'], *args, np.zeros(3, np.uint8),
                     np.zeros(3, np.int16), np.empty(3, np.int64))  # fmt: skip
    with pytest.raises(TypeError):
        C.frame_json(["can0"], [b'"x"'], *args, np.zeros(3, np.uint8),
                     np.zeros(3, np.int16), np.empty(3, np.int64))  # fmt: skip
