"""The bulk ASC reader gives exactly the rows and problems of the line-by-line reader."""

from __future__ import annotations

import random
import sys

import numpy as np
import pytest
from conftest import ROOT, SAMPLES, real_file
from readers_util import run

from cananalyze.core.errors import InputError
from cananalyze.formats.logs import asc, candump

sys.path.insert(0, str(ROOT / "benchmarks"))


def assert_same(data: bytes, batch_size: int = 1000, chunk: int | None = None) -> int:
    if chunk is not None:
        old, candump.CHUNK = asc.CHUNK, chunk
        asc.CHUNK = chunk
    try:
        got, ctx, _ = run(asc.read, data, batch_size=batch_size)
    finally:
        if chunk is not None:
            asc.CHUNK = candump.CHUNK = old
    want, ref, _ = run(asc.read_per_line, data, batch_size=batch_size)
    for col in ("t", "can_id", "flags", "dlc", "data", "line"):
        assert np.array_equal(getattr(got, col), getattr(want, col)), col
    assert [got.channels[c] for c in got.channel] == [want.channels[c] for c in want.channel]
    assert got.long_data.keys() == want.long_data.keys()
    assert ctx.problems.count == ref.problems.count
    assert [str(p) for p in ctx.problems.shown] == [str(p) for p in ref.problems.shown]
    assert (ctx.frames, ctx.absolute_time, ctx.start_time) == (
        ref.frames,
        ref.absolute_time,
        ref.start_time,
    )
    return len(got)


@pytest.mark.parametrize(
    "name",
    [
        "logfile.asc",
        "issue_1256.asc",
        "issue_1299.asc",
        "logfile_errorframes.asc",
        "test_CanFdMessage64.asc",
        "test_CanMessage.asc",
        "test_CanRemoteMessage.asc",
        "single_frame_us_locale.asc",
    ],
)
def test_python_can_fixtures(name: str) -> None:
    data = real_file(f"hardbyte__python-can/{name}").read_bytes()
    assert assert_same(data) > 0
    assert_same(data, batch_size=3, chunk=97)


def test_sample_and_benchmark_mix(tmp_path) -> None:
    from generate import generate

    from cananalyze.formats.logfile import write_log

    assert assert_same((SAMPLES / "demo.asc").read_bytes()) > 100
    path = tmp_path / "mix.asc"
    write_log(generate(30_000), path)
    assert assert_same(path.read_bytes(), batch_size=4096, chunk=65536) == 30_000


HEADER = b"date Thu Jan 01 00:00:00.0 2026\nbase hex  timestamps absolute\ninternal events logged\n"


def _random_asc(rng: random.Random) -> bytes:
    lines = []
    if rng.random() < 0.8:
        lines += HEADER.splitlines()
    t = 0.0
    for _ in range(rng.randint(1, 60)):
        t += rng.choice([0.0001, 0.25, 1.5])
        r = rng.random()
        ch = rng.choice(["1", "2", "01", "12"])
        n = rng.randint(0, 9)
        ident = rng.choice(["181", "7FF", "800", "1FFFFFFFx", "20000000x", "18FF50E5X", "zz", "0"])
        data = " ".join(
            rng.choice(["00", "A5", "f", "ZZ", "7"]) for _ in range(min(n, 8) + rng.randint(-1, 1))
        )
        sep = rng.choice([" ", "  ", "\t"])
        if r < 0.6:
            line = (
                f"{t:.6f}{sep}{ch}  {ident}{sep}{rng.choice(['Rx', 'Tx', 'rx'])}   d {n:X} {data}"
            )
        elif r < 0.65:
            line = f"{t:.6f} {ch}  {ident} Rx r {n}"
        elif r < 0.7:
            line = f"{t:.6f} {ch} ErrorFrame"
        elif r < 0.75:
            line = f"{t:.6f} CANFD {ch} Rx 181 1 0 8 8 {data}"
        elif r < 0.8:
            line = rng.choice(
                [
                    "Begin Triggerblock Thu Jan 01 00:00:05.0 2026",
                    "base dec timestamps relative",
                    "base hex timestamps absolute",
                    " BaSE dec  timestamps absolute",  # any case, after a blank
                    "// comment",
                    "End TriggerBlock",
                    "garbage here",
                ]
            )
        elif r < 0.85:
            line = f"{t:.6e} {ch} 181 Rx d 1 00"
        elif r < 0.9:
            line = f"{t:.6f} Start of measurement"
        elif r < 0.95:
            line = f"{t:.3f} {ch} 123 Rx d 2 01 02  Length = 0 BitCount = 64 ID = 291"
        else:  # separators str.split() knows and a byte it does not split on
            odd = rng.choice([" ", "\x0b", "\x01", "\x85", "\xa0", "\x1f"])
            line = f"{t:.6f}\x0b{ch} 181{odd}Rx d 1 00"
        line = line.encode("latin-1")
        lines.append(line)
        continue
    eol = rng.choice([b"\n", b"\r\n"])
    return eol.join(lines) + (eol if rng.random() < 0.7 else b"")


@pytest.mark.parametrize("seed", range(150))
def test_random_logs(seed: int) -> None:
    rng = random.Random(seed)
    data = _random_asc(rng)
    assert_same(data, batch_size=rng.choice([2, 7, 1000]), chunk=rng.choice([None, 64, 200]))


def test_strict_stops_at_the_same_line() -> None:
    data = HEADER + b"0.1 1 181 Rx d 1 00\n0.2 1 181 Rx d 2 00 ZZ\n0.3 1 181 Rx d 1 00\n"
    with pytest.raises(InputError, match="line 5") as a:
        run(asc.read, data, strict=True)
    with pytest.raises(InputError) as b:
        run(asc.read_per_line, data, strict=True)
    assert str(a.value) == str(b.value)


_ODD = [
    " ",
    "  ",
    " " * 9,
    " " * 17,
    "\t",
    " \t ",
    "\r",
    "\x0b",
    "\x1c",
    "\x01",
    "\x85",
    "\xa0",
    "",
]


@pytest.mark.parametrize("seed", range(40))
def test_odd_bytes_around_every_field(seed: int) -> None:
    """The one-pass C parser checks each field as it reads it: any byte between, inside or
    after the fields (space runs it skips eight at a time, controls and latin-1 spaces the
    line parser splits on, bytes it does not) gives the line parser's rows and problems."""
    rng = random.Random(seed)
    fields = ["0.250000", "1", "181", "Rx", "d", "3", "01", "A5", "ff"]
    lines = [HEADER.rstrip(b"\n")]
    for _ in range(400):
        seps = [
            rng.choice(_ODD) if rng.random() < 0.3 else " " * rng.randint(1, 20) for _ in fields
        ]
        line = "".join(s + f for s, f in zip(seps, fields, strict=True))
        if rng.random() < 0.5:  # what follows the last data byte is never read
            line += rng.choice(_ODD) + rng.choice(["", "x", "\xff\x00", "Length = 0", "\x85 7"])
        lines.append(line.encode("latin-1"))
    data = b"\n".join(lines) + b"\n"
    assert_same(data, batch_size=rng.choice([7, 1000]), chunk=rng.choice([None, 4096]))


def test_frame_lines_never_reach_the_line_parser(monkeypatch) -> None:
    """The compiled pass takes every classic data-frame line (the bulk of a log); the line
    parser sees only the header and event lines."""
    if asc.speedups.C is None:
        pytest.skip("needs the compiled helper")
    seen: list[int] = []
    real = asc._LineParser.line

    def counted(self, n, raw):
        seen.append(n)
        return real(self, n, raw)

    monkeypatch.setattr(asc._LineParser, "line", counted)
    frames = [
        f" {i / 1000:.6f} 1  {0x181 + i % 4:X}     Rx   d 2 0{i % 10} FF" for i in range(5000)
    ]
    body = "\n".join(frames[:2500] + [" 2.5 Start of measurement"] + frames[2500:])
    data = HEADER + body.encode() + b"\n"
    monkeypatch.setattr(asc, "CHUNK", 8192)
    got, _, _ = run(asc.read, data, batch_size=1000)
    assert len(got) == 5000 and seen == [1, 2, 3, 2504]
    monkeypatch.undo()
    assert assert_same(data, batch_size=1000, chunk=8192) == 5000


def test_chunk_of_many_event_lines(monkeypatch) -> None:
    """More non-frame lines in a chunk than the C pass has room for at first: it counts
    the lines and runs again, with the same rows and problems."""
    if asc.speedups.C is None:
        pytest.skip("needs the compiled helper")
    C = asc.speedups.C
    results: list[int] = []
    real = C.asc_chunk

    def spied(*args):
        got = real(*args)
        results.append(got[0])
        return got

    monkeypatch.setattr(C, "asc_chunk", spied)
    lines = [b"0.1 1 181 Rx d 1 00"]
    for i in range(3000):
        lines.append(b"// c" if i % 3 else b"1.5 1 181 Rx r")
        lines.append(b"x")
    data = HEADER + b"\n".join(lines) + b"\n"
    assert assert_same(data, batch_size=500) == 1001
    assert -1 in results  # the first room was too small, and the second run gave the rows
