"""PEAK TRC reader against python-can's TRCReader on real traces, and on bad input."""

from __future__ import annotations

import datetime

import can
import pytest
from conftest import real_file
from readers_util import assert_same_as_python_can, run

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_EXT, FLAG_RTR, FLAG_TX
from cananalyze.formats.logs import trc

FIXTURES = [
    ("hardbyte__python-can/test_CanMessage.trc", 2),
    ("hardbyte__python-can/test_CanMessage_V1_0_BUS1.trc", 11),
    ("hardbyte__python-can/test_CanMessage_V1_1.trc", 11),
    ("hardbyte__python-can/test_CanMessage_V1_3.trc", 11),
    ("hardbyte__python-can/test_CanMessage_V2_0_BUS1.trc", 11),
    ("hardbyte__python-can/test_CanMessage_V2_1.trc", 11),
    # frame counts stated in SOURCES.md
    ("hilch__canopen-message-interpreter/pcan1.trc", 11283),
    ("hilch__canopen-message-interpreter/pcan2.trc", 6968),
    ("hilch__canopen-message-interpreter/pcan3.trc", 45422),
]


@pytest.mark.parametrize("name,count", FIXTURES)
def test_same_rows_as_python_can(name, count):
    path = real_file(name)
    batch, ctx, _ = run(trc.read, path, batch_size=4096)
    expected = list(can.TRCReader(str(path)))
    assert len(batch) == count
    assert_same_as_python_can(batch, expected, channel_offset=0)
    assert ctx.problems.count == 0 and ctx.format == "trc"
    assert ctx.absolute_time == ("V1_0" not in name)


def test_pcan3_columns_bus_and_start_time():
    batch, ctx, _ = run(trc.read, real_file("hilch__canopen-message-interpreter/pcan3.trc"))
    start = datetime.datetime.fromtimestamp(ctx.start_time, datetime.UTC)
    assert (start.year, start.month, start.day, start.hour, start.minute) == (2024, 3, 13, 8, 51)
    # "1     16310.827 DT 1      0770 Rx -  1    05"
    assert batch.line[0] == 23 and batch.can_id[0] == 0x770 and batch.payload(0) == b"\x05"
    assert batch.t[0] - ctx.start_time == pytest.approx(16.310827)
    assert batch.channels == ("1",)
    assert int((batch.flags & FLAG_RTR != 0).sum()) == 1659  # node guarding, per SOURCES.md


def test_pcan2_rtr_and_v1_1_start():
    batch, ctx, _ = run(trc.read, real_file("hilch__canopen-message-interpreter/pcan2.trc"))
    assert int((batch.flags & FLAG_RTR != 0).sum()) == 187
    assert datetime.datetime.fromtimestamp(ctx.start_time, datetime.UTC).date() == datetime.date(
        2022, 4, 5
    )


BAD_V21 = b""";$FILEVERSION=2.1
;$STARTTIME=44548.6028595139
;$COLUMNS=N,O,T,B,I,d,R,L,D
      1     17535.400 DT 1  00000100 Tx -  8    00 01 02 03 04 05 06 07
      2     17540.300 ST 1         - Rx -  4    00 00 00 08
      3     17700.300 DT 1      0G00 Tx -  8    00 00 00 00 00 00 00 00
      4     17700.400 DT 1      0100 Tx -  8    00 00 00
      5     17700.500 DT 1      0100 Tx -  X    00
      6     17700.600 DT 1      0100 Tx -  2    0Z 00
garbage
      8     17701.000 RR 2      0704 Rx -  1
      9     17702.000
"""


def test_bad_lines_are_skipped_and_counted():
    batch, ctx, _ = run(trc.read, BAD_V21, source="bad.trc")
    assert batch.can_id.tolist() == [0x100, 0x704]
    assert batch.line.tolist() == [4, 11]
    assert batch.flags.tolist() == [FLAG_EXT | FLAG_TX, FLAG_RTR]
    assert [batch.channel_name(i) for i in range(2)] == ["1", "2"]
    assert [p.location for p in ctx.problems.shown] == [
        "line 6",
        "line 7",
        "line 8",
        "line 9",
        "line 10",
        "line 12",
    ]
    with pytest.raises(InputError, match=r"bad\.trc:line 6: invalid identifier"):
        run(trc.read, BAD_V21, strict=True, source="bad.trc")


def test_v1_1_truncated_last_line():
    text = real_file("hilch__canopen-message-interpreter/pcan1.trc").read_bytes()
    cut = text[: text.rindex(b"\n", 0, len(text) - 1) + 20]  # last line cut short
    batch, ctx, _ = run(trc.read, cut)
    assert len(batch) == 11282 and ctx.problems.count == 1
    assert ctx.problems.shown[0].location == "line 11299"


def test_sniff():
    assert trc.sniff(real_file("hilch__canopen-message-interpreter/pcan1.trc").read_bytes())
    assert trc.sniff(real_file("hardbyte__python-can/test_CanMessage_V1_0_BUS1.trc").read_bytes())
    assert not trc.sniff(real_file("collin80__SavvyCAN/CarBusAnalyzer.trc").read_bytes())
    assert not trc.sniff(real_file("hilch__canopen-message-interpreter/ixxat1.trc").read_bytes())


# issue 38 item 5: blank lines are skipped in bulk (text_lines' skip_blank), read as before


def _with_blank_lines(text: bytes, every: int = 1, after: int = 0) -> tuple[bytes, list[int]]:
    """The text with blank lines (empty, CR only, spaces and tabs, runs of a thousand)
    after each of its lines past `after`; and the new number of each old line."""
    blanks = [b"\n", b"\r\n", b"  \t \n", b"\n" * 1000, b"\r\n \n\n"]
    out, where, line = [], [], 0
    for i, row in enumerate(text.splitlines(keepends=True)):
        line += 1
        where.append(line)
        out.append(row)
        if i + 1 > after and i % every == 0:
            extra = blanks[i % len(blanks)]
            out.append(extra)
            line += extra.count(b"\n")
    return b"".join(out), where


@pytest.mark.parametrize("name,count", FIXTURES[-3:] + FIXTURES[:2])
def test_blank_lines_read_as_python_can_reads_them(name, count, tmp_path):
    """A trace with up to 200,000 blank lines among its frames: python-can's TRCReader
    (which skips blank lines one by one) reads the same frames, at the lines they are on."""
    plain = real_file(name).read_bytes()
    head = next(i for i, row in enumerate(plain.splitlines()) if not row.startswith(b";"))
    # (python-can takes the first line after the ';' header for a frame: blank lines after it)
    text, where = _with_blank_lines(plain, every=1 if count < 100 else 13, after=head + 1)
    path = tmp_path / "blank.trc"
    path.write_bytes(text)
    batch, ctx, _ = run(trc.read, path, batch_size=4096)
    assert len(batch) == count and ctx.problems.count == 0
    assert_same_as_python_can(batch, list(can.TRCReader(str(path))), channel_offset=0)
    before, _, _ = run(trc.read, plain, batch_size=4096)
    assert batch.line.tolist() == [where[k - 1] for k in before.line.tolist()]
    lines = text.split(b"\n")
    assert all(lines[k - 1].strip() for k in batch.line.tolist())


def _old_text_lines(stream, ctx=None, max_line=None):
    """text_lines as it was before issue 38 (one readline per line): the reference."""
    n = 0
    while True:
        raw = stream.readline(max_line)
        if not raw:
            return
        n += 1
        if len(raw) == max_line and not raw.endswith(b"\n"):
            size = len(raw)
            while True:
                more = stream.readline(max_line)
                size += len(more)
                if not more or more.endswith(b"\n"):
                    break
            if ctx is not None:
                ctx.problems.add(
                    ctx.source,
                    f"line {n}",
                    f"line of {size} bytes is too long for a log line, skipped",
                )
                continue
        yield n, raw.decode("latin-1").rstrip("\r\n")


@pytest.mark.parametrize("seed", range(40))
def test_text_lines_as_one_readline_per_line(seed, monkeypatch):
    """Random text of blank runs (empty, CR, spaces, VT/FF), long lines around MAX_LINE,
    CRLF, latin-1 bytes and no last newline, cut in blocks of a few bytes: the lines and
    problems of one readline per line; with skip_blank, those but the blank lines."""
    import io
    import random

    from cananalyze.core.errors import ProblemLog
    from cananalyze.formats.logs import _rows
    from cananalyze.formats.registry import ReadContext

    rnd = random.Random(seed)
    limit = rnd.choice([8, 16, 40])
    monkeypatch.setattr(_rows, "MAX_LINE", limit)
    monkeypatch.setattr(_rows, "BLOCK", rnd.choice([1, 3, 7, 64, 1 << 20]))
    pieces = [b"\n", b"\r\n", b" ", b"\t", b"\x0b\x0c", b"x", b"ab c", b"\xe9\xa0", b"\x85"]
    parts = []
    for _ in range(rnd.randrange(0, 120)):
        kind = rnd.random()
        if kind < 0.3:
            parts.append(b"\n" * rnd.randrange(1, 60))
        elif kind < 0.4:
            parts.append(rnd.choice([b" ", b"\t", b"\r"]) * rnd.randrange(limit - 2, limit + 3))
        elif kind < 0.5:
            parts.append(b"y" * rnd.randrange(limit - 2, limit + 3))
        else:
            parts.append(rnd.choice(pieces))
    data = b"".join(parts)
    for with_ctx in (True, False):
        for skip in (False, True):
            ctx = ReadContext(source="m", problems=ProblemLog()) if with_ctx else None
            got = list(_rows.text_lines(io.BytesIO(data), ctx=ctx, skip_blank=skip))
            ref_ctx = ReadContext(source="m", problems=ProblemLog()) if with_ctx else None
            want = list(_old_text_lines(io.BytesIO(data), ref_ctx, limit))
            if skip:
                want = [(n, s) for n, s in want if s.strip(" \t\r\x0b\x0c")]
            assert got == want, (data, with_ctx, skip)
            if with_ctx:
                assert [str(p) for p in ctx.problems.shown] == [
                    str(p) for p in ref_ctx.problems.shown
                ]
