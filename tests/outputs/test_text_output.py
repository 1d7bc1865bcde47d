"""The columnar text writer prints exactly what the per-row writer prints.

`lines_per_row` is the original row-by-row implementation; every input is
written both ways, with and without colour and with several filters.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SAMPLES, real_file
from helpers.broken_disk import broken_text_stream

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR, FLAG_TX, FrameBatch, from_rows
from cananalyze.formats.source import open_log
from cananalyze.outputs.text.writer import TextWriter, lines_per_row
from cananalyze.pipeline import Options, build_decoder

sys.path.insert(0, str(ROOT / "benchmarks"))


def _masks(batch, t0: float):
    n = len(batch)
    yield None
    yield np.isin(batch.node, [3, 5, 10])
    yield np.isin(batch.service, [7, 8, 4])
    yield (batch.frames.t - t0) >= 0.05
    yield np.zeros(n, bool)
    yield np.random.default_rng(n).random(n) < 0.3


def _check(batches, color: bool) -> int:
    lines_checked = 0
    for m_idx in range(6):
        w = TextWriter(io.StringIO(), color=color)
        ref: list[str] = []
        for b in batches:
            t0 = w.t0 if w.t0 is not None else float(b.frames.t[0]) if len(b) else None
            mask = list(_masks(b, t0 or 0.0))[m_idx] if len(b) else None
            w.write(b, mask)
            ref += lines_per_row(b, mask, w.t0 or 0.0, color, False)
        got = w.out.getvalue()
        want = "".join(line + "\n" for line in ref)
        assert got == want, next(
            (
                f"line {k}: {a!r} != {b!r}"
                for k, (a, b) in enumerate(zip(got.split("\n"), ref, strict=False))
                if a != b
            ),
            "length",
        )
        lines_checked += len(ref)
    return lines_checked


def _decode(path: Path, batch_size: int | None = None):
    dec = build_decoder(Options())
    src = open_log(path)
    out = [dec.decode(fb) for fb in src.batches()]
    out.append(dec.finish())
    return out


@pytest.mark.parametrize("color", [False, True])
@pytest.mark.parametrize("name", ["demo.log", "demo.asc", "demo.blf"])
def test_samples(name: str, color: bool) -> None:
    assert _check(_decode(SAMPLES / name), color) > 100


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan1.trc",
        "hilch__canopen-message-interpreter/ixxat1.trc",
        "isPointless__Sevcon/can_180209_154604.txt",
        "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
        "SeonilChoi__CANOPEN-SDK/log.txt",
    ],
)
def test_real_logs(rel: str) -> None:
    assert _check(_decode(real_file(rel)), color=False) > 10
    assert _check(_decode(real_file(rel)), color=True) > 10


def test_benchmark_mix() -> None:
    from generate import generate

    fb = generate(20_000)
    dec = build_decoder(Options())
    batches = [dec.decode(fb.take(slice(s, s + 7000))) for s in range(0, len(fb), 7000)]
    assert _check(batches + [dec.finish()], color=False) > 20_000


def _odd_batch() -> FrameBatch:
    """Times that round on a half microsecond, go backwards, grow large; ext/err/RTR/TX, 2 channels."""
    rows = [
        (100.0, 0x181, bytes(8)),
        (100.0078125, 0x080, b"\x07"),  # rel 0.0078125: an exact half microsecond
        (99.5, 0x701, b"\x05"),  # earlier than the first frame
        (100.0000005, 0x000, b"\x01\x00"),
        (100.0 + 123456.5, 0x18FF50E5, b"\x01\x02\x03", FLAG_EXT),
        (100.25, 0x701, b"", FLAG_RTR),
        (100.3, 0x20000004, b"", FLAG_ERR, 1),
        (100.4, 0x081, b"\x00\x10\x01\x00\x00\x00\x00\x00", FLAG_TX, 1),
        (100.5, 0x7E5, b"\x04\x01"),
        (100.6, 0x100, b"\x64\x00\x00\x00\xed\x3b"),
        (100.7, 0x281, b"", FLAG_RTR),
        (100.8, 0x080, b""),
        (100.9, 0x70A, b"\x85"),
        (101.0, 0x123, b"\xaa" * 5),
    ]
    return from_rows(rows, channels=("can0", "vcan10"))


@pytest.mark.parametrize("color", [False, True])
def test_odd_rows(color: bool) -> None:
    dec = build_decoder(Options())
    b = dec.decode(_odd_batch())
    assert _check([b], color) > 10


def test_fd_long_payload_falls_back() -> None:
    fb = from_rows([(1.0, 0x181, bytes(range(12)), 0x08), (1.1, 0x080, b"\x01")])
    dec = build_decoder(Options())
    assert _check([dec.decode(fb)], color=False) > 1


def test_writes_to_a_real_file(tmp_path: Path) -> None:
    batches = _decode(SAMPLES / "demo.log")
    path = tmp_path / "out.txt"
    with open(path, "w", encoding="utf-8") as out:
        w = TextWriter(out)
        for b in batches:
            w.write(b)
    ref = []
    t0 = float(batches[0].frames.t[0])
    for b in batches:
        ref += lines_per_row(b, None, t0, False, False)
    assert path.read_text(encoding="utf-8") == "".join(x + "\n" for x in ref)


def _decode_cli(argv: list[str]):
    from cananalyze.cli.common import options
    from cananalyze.cli.main import build_parser

    args = build_parser().parse_args(["decode", *argv])
    dec = build_decoder(options(args))
    out = [dec.decode(fb) for fb in open_log(args.log).batches()]
    out.append(dec.finish())
    return out


def test_pdo_signals_from_a_device_profile() -> None:
    eds = real_file("jclinton830__canopen_test/roboteq_motor_controllers_v80.eds")
    log = real_file("jclinton830__canopen_test/candump.txt")
    batches = _decode_cli([str(log), "--eds", f"12={eds}"])
    assert any(b.signals for b in batches)
    assert _check(batches, color=False) > 10
    assert _check(batches, color=True) > 10


def test_signals_of_a_builtin_device(tmp_path: Path) -> None:
    log = tmp_path / "x.log"
    log.write_text("(1.0) can0 285#E803000000000000\n(1.1) can0 080#\n(1.2) can0 285#E8030000\n")
    batches = _decode_cli([str(log), "--device", "5=dat7014"])
    assert _check(batches, color=False) >= 3


@pytest.mark.slow
def test_benchmark_mix_with_devices() -> None:
    """16 DAT 7014 nodes: TPDO2 rows carry four scaled signals, formatted per column."""
    from generate import generate

    fb = generate(30_000, seed=3)
    batches = _decode_cli_batch(fb, [a for k in range(1, 17) for a in ("--device", f"{k}=dat7014")])
    assert sum(len(sb.rows) for b in batches for sb in b.signals) > 3000
    assert _check(batches, color=False) > 30_000
    assert _check(batches, color=True) > 30_000


def _decode_cli_batch(fb, argv: list[str], step: int = 9000):
    from cananalyze.cli.common import options
    from cananalyze.cli.main import build_parser

    args = build_parser().parse_args(["decode", "x.log", *argv])
    dec = build_decoder(options(args))
    out = [dec.decode(fb.take(slice(s, s + step))) for s in range(0, len(fb), step)]
    out.append(dec.finish())
    return out


def test_emcy_rows() -> None:
    """EMCY text per (code, register) with the vendor bytes in lower-case hex, any DLC."""
    rows = [
        (1.0 + k / 100, 0x081 + k % 5, bytes([code & 0xFF, code >> 8, reg, *extra]))
        for k, (code, reg, extra) in enumerate(
            [
                (0x1000, 0x01, b""),
                (0x1000, 0x01, b"\xab"),
                (0x2310, 0x03, b"\x01\x02\x03\x04\x05"),
                (0x0000, 0x00, b"\x00\x00\x00\x00\x00"),
                (0x0000, 0x00, b""),
                (0xFF00, 0xFF, b"\xde\xad"),
                (0x8130, 0x11, b"\xfe\xdc\xba\x98"),
                (0x1234, 0x80, b"\x00\x00\x00"),
            ]
        )
    ]
    rows += [(2.0, 0x082, b"\x10"), (2.1, 0x083, b"")]  # malformed: per row
    dec = build_decoder(Options())
    assert _check([dec.decode(from_rows(rows)), dec.finish()], color=False) >= 10


@pytest.fixture(params=["compiled", "numpy"])
def both_paths(request, monkeypatch) -> None:
    """The test runs with the compiled helper and with its numpy twin."""
    from cananalyze.runtime import speedups

    if request.param == "numpy":
        monkeypatch.setattr(speedups, "C", None)
    elif speedups.C is None:
        pytest.skip("compiled helper not in use")


def test_signal_values_of_every_kind(both_paths) -> None:
    """Signal columns as text: floats (ties, exponents, NaN, -0), integers to 64 bits,
    booleans; the compiled helper's floats and the numpy twin's alike."""
    from cananalyze.core.columns.numtext import g6_text, int_text, value_text

    rng = np.random.default_rng(5)
    floats = np.concatenate(
        [
            rng.integers(-32768, 32768, 5000) * 0.1,
            rng.standard_normal(5000) * 10.0 ** rng.integers(-9, 10, 5000),
            rng.integers(-1000, 1000, 2000) / 8.0,  # exact halves: ties
            [0.0, -0.0, np.nan, np.inf, -np.inf, 1e-5, 1e-4, 999999.5, 99999.95, 1e6, 5e-324],
            [123456.5, 1234565.0, 9.999995, -0.000123456789, 1.7976931348623157e308, -np.nan],
        ]
    )

    def text(m: np.ndarray) -> list[str]:
        return [bytes(r[r != 0]).decode() for r in m]

    assert text(g6_text(floats)) == [f"{v:.6g}" for v in floats.tolist()]
    ints = np.concatenate(
        [
            rng.integers(-(2**63), 2**63 - 1, 500, dtype=np.int64),
            np.array([0, -1, 9, 10, -10, np.iinfo(np.int64).min], np.int64),
        ]
    )
    assert text(int_text(ints)) == [str(v) for v in ints.tolist()]
    big = np.array([0, 1, 2**63, 2**64 - 1], np.uint64)
    assert text(int_text(big)) == [str(v) for v in big.tolist()]
    assert text(value_text(np.array([True, False]))) == ["True", "False"]
    assert text(value_text(np.array([1.5, 2], object))) == ["1.5", "2"]


def test_time_column_is_python_fixed_point(both_paths) -> None:
    """Each line's time, `f"{t:12.6f}"` of the time since the first frame: near ties,
    days-long logs, negative, -0.0 and non-finite ones on both paths."""
    from cananalyze.outputs.text import writer

    rng = np.random.default_rng(8)
    rel = np.concatenate(
        [
            np.cumsum(rng.integers(1, 5000, 20000)) / 1e6,  # candump's microseconds
            rng.random(3000) * 1e7,  # past the 12-character field
            (rng.integers(0, 10**9, 2000) + 0.5) / 1e6,  # half-microsecond ties
            [0.0, -0.0, -1.5, 1e6, 999999.9999995, 5e-7, 1.5e-6, 1e15, np.nan, np.inf, -np.inf],
            [1e30, 1e40, -1e300],  # past the compiled pass's 40 columns: the twin formats
        ]
    )
    got = [bytes(r[r != 0]).decode() for r in writer._time_column(rel)]
    assert got == [f"{x:12.6f}" for x in rel.tolist()]


def test_frame_columns_compiled_as_numpy() -> None:
    """Identifier, length and data columns: the compiled pass and the numpy twin give
    the same matrix for 11- and 29-bit identifiers, error frames, remote requests,
    lengths 0..15 and CAN FD lengths; and a classic row reads as the per-row writer's."""
    from cananalyze.outputs.text import writer
    from cananalyze.runtime import speedups

    if getattr(speedups.C, "frame_text", None) is None:
        pytest.skip("compiled helper not in use")
    rng = np.random.default_rng(2)
    n = 20000
    can_id = rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32)
    can_id[: n // 2] &= 0x7FF
    flags = rng.choice([0, 0, 0, 1, 2, 3, 4, 5, 6, 7], n).astype(np.uint8)
    dlc = rng.choice([*range(16), 20, 32, 48, 64], n).astype(np.uint8)
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    args = (can_id, flags, dlc, data, (flags & 2) != 0)
    compiled = writer._frame_columns(*args)
    c = speedups.C
    try:
        speedups.C = None
        twin = writer._frame_columns(*args)
    finally:
        speedups.C = c
    assert np.array_equal(compiled, twin)
    row = bytes(compiled[0][compiled[0] != 0]).decode()
    ident = f"{int(can_id[0]):08X}" if flags[0] & 5 else f"{int(can_id[0]):03X}"
    shown = (
        "remote request"
        if flags[0] & 2
        else " ".join(f"{b:02X}" for b in data[0][: min(dlc[0], 8)])
    )
    assert row == f"{ident:>8}  [{dlc[0]}]  {shown:<23}"


def test_background_writer_writes_the_same(tmp_path: Path) -> None:
    from generate import generate

    batches = _decode_cli_batch(
        generate(20_000, seed=4), [a for k in (1, 5, 9) for a in ("--device", f"{k}=dat7014")]
    )
    paths = []
    for background in (False, True):
        path = tmp_path / f"out{background}.txt"
        with open(path, "w", encoding="utf-8") as out:
            w = TextWriter(out, background=background)
            for b in batches:
                w.write(b)
            w.close()
        paths.append(path)
    assert paths[0].read_bytes() == paths[1].read_bytes()


def test_background_writer_raises_in_close() -> None:
    batches = _decode(SAMPLES / "demo.log")
    w = TextWriter(broken_text_stream(), background=True)
    assert w._sink.background
    with pytest.raises(OSError, match="disk full"):
        for b in batches:
            w.write(b)
        w.close()


@pytest.mark.parametrize("share", [0.0, 0.01, 0.7, 1.0])
def test_key_groups_partition_rows_as_a_sort_would(share: float) -> None:
    """_key_groups (counting over a dense key) groups the keyed rows exactly as np.unique
    of the full key does; unkeyed rows are group 0; first_at is each group's first row."""
    from cananalyze.outputs.text.writer import _BYTE_MATTERS, _LENGTH_MATTERS, _key_groups
    from cananalyze.protocol.services import Service

    rng = np.random.default_rng(int(share * 100))
    n = 5000
    svc = rng.integers(0, 20, n).astype(np.uint8)
    pdo = rng.integers(0, 5, n).astype(np.uint8)
    rtr = rng.random(n) < 0.1
    dlc = rng.integers(0, 9, n).astype(np.uint8)
    data = rng.integers(0, 4, (n, 8)).astype(np.uint8)
    keyed = rng.random(n) < share
    inv, first_at = _key_groups(svc, pdo, rtr, dlc, data, keyed)
    is_pdo = (svc == Service.TPDO) | (svc == Service.RPDO)
    first = np.where((dlc > 0) & _BYTE_MATTERS[svc], data[:, 0].astype(np.int64), 256)
    first = np.where(_LENGTH_MATTERS[svc], dlc, first)  # errctl_invalid: its length, in words
    key = ((svc.astype(np.int64) * 256 + np.where(is_pdo, pdo, 0)) * 2 + (rtr & is_pdo)) * 257
    key = np.where(keyed, key + first, -1)
    uniq, first_ref, inv_ref = np.unique(key, return_index=True, return_inverse=True)
    assert (inv[~keyed] == 0).all()
    assert len(first_at) == len(uniq) + (0 if (~keyed).any() else 1)
    pairs = set(zip(inv.tolist(), inv_ref.ravel().tolist(), strict=True))
    assert len(pairs) == len(uniq) == len(set(inv.tolist()))  # one group for one key, and back
    for g, i in enumerate(first_at.tolist()[1:], start=1):
        assert inv[i] == g and not (inv[:i] == g).any()


def test_cia402_signal_words_as_per_row() -> None:
    """Statusword/controlword words of the columnar writer equal the per-row texts."""
    from cananalyze.cli.common import options
    from cananalyze.cli.main import build_parser

    log = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    dec = build_decoder(
        options(build_parser().parse_args(["decode", str(log), "--device", "11=cia402"]))
    )
    batches = [dec.decode(fb) for fb in open_log(log).batches()] + [dec.finish()]
    assert any(sb.words for b in batches for sb in b.signals)
    assert _check(batches, False) > 1000
