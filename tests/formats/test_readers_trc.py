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
