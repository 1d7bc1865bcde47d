"""Vector ASC reader against python-can's ASCReader on real fixtures, and on bad input."""

from __future__ import annotations

import gzip

import can
import pytest
from conftest import real_file
from readers_util import assert_same_as_python_can, run

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX
from cananalyze.formats.logs import asc

FIXTURES = [
    "issue_1256.asc",
    "issue_1299.asc",
    "logfile.asc",
    "logfile_errorframes.asc",
    "single_frame.asc",
    "single_frame_us_locale.asc",
    "test_CanErrorFrames.asc",
    "test_CanFdMessage.asc",
    "test_CanFdMessage64.asc",
    "test_CanFdRemoteMessage.asc",
    "test_CanMessage.asc",
    "test_CanRemoteMessage.asc",
]


@pytest.mark.parametrize("name", FIXTURES)
def test_same_rows_as_python_can(name):
    path = real_file(f"hardbyte__python-can/{name}")
    batch, ctx, _ = run(asc.read, path, batch_size=7)
    expected = list(can.ASCReader(str(path), relative_timestamp=False))
    assert len(batch) > 0
    assert_same_as_python_can(batch, expected)
    assert ctx.problems.count == 0
    assert ctx.format == "asc"
    assert ctx.absolute_time and ctx.start_time is not None
    assert ctx.frames == len(batch)


def test_gzipped_fixture_reads_like_the_plain_one():
    path = real_file("hardbyte__python-can/test_CanMessage.asc.gz")
    plain, _, _ = run(asc.read, real_file("hardbyte__python-can/test_CanMessage.asc"))
    batch, _, _ = run(asc.read, gzip.decompress(path.read_bytes()))
    assert batch.can_id.tolist() == plain.can_id.tolist() == [0xC8, 0x6F9]
    assert batch.data.tolist() == plain.data.tolist()


def test_known_values_of_one_file():
    batch, ctx, _ = run(asc.read, real_file("hardbyte__python-can/test_CanMessage.asc"))
    # "2.5010 2 C8 Tx d 8 09 08 07 06 05 04 03 02" after "Begin Triggerblock ... 10:06:13.191 PM"
    assert batch.line.tolist() == [7, 8]
    assert batch.flags[0] == FLAG_TX and batch.flags[1] == 0
    assert batch.payload(0) == bytes([9, 8, 7, 6, 5, 4, 3, 2])
    assert batch.channel_name(0) == "2" and batch.channel_name(1) == "1"
    assert batch.t[0] - ctx.start_time == pytest.approx(2.501)


def test_fd_rtr_error_and_ext_flags():
    fd, _, _ = run(asc.read, real_file("hardbyte__python-can/test_CanFdMessage64.asc"))
    assert fd.dlc.tolist() == [64, 64] and fd.flags[1] & FLAG_EXT and fd.flags[0] & FLAG_FD
    assert len(fd.long_data) == 2 and len(fd.payload(0)) == 64
    rtr, _, _ = run(asc.read, real_file("hardbyte__python-can/test_CanRemoteMessage.asc"))
    assert all(f & FLAG_RTR for f in rtr.flags) and rtr.dlc.tolist() == [0, 0, 8]
    err, _, _ = run(asc.read, real_file("hardbyte__python-can/test_CanErrorFrames.asc"))
    assert all(f & FLAG_ERR for f in err.flags)


BAD = b"""date Sat Sep 30 15:06:13.191 2017
base hex  timestamps absolute
internal events logged
Begin Triggerblock Sat Sep 30 15:06:13.191 2017
   0.000000 Start of measurement
   1.000000 1  100             Rx   d 2 01 02
this is not a log line
   1.100000 1  1G0             Rx   d 2 01 02
   1.200000 1  101             Rx   d 2 01 ZZ
   1.300000 1  102             Rx   d X 01 02
   1.400000 1  103             Rx   d 8 01 02
   1.5x0000 1  104             Rx   d 1 01
   1.600000 1  18EBFF00x       Tx   d 1 AA
   1.700000 1  105             Rx   d 2 01
"""


def test_bad_lines_are_skipped_and_counted_with_line_numbers():
    batch, ctx, _ = run(asc.read, BAD, source="bad.asc")
    assert batch.can_id.tolist() == [0x100, 0x18EBFF00]
    assert batch.line.tolist() == [6, 13]
    assert batch.flags[1] == FLAG_EXT | FLAG_TX
    assert ctx.problems.count == 7
    where = [p.location for p in ctx.problems.shown]
    assert where == ["line 7", "line 8", "line 9", "line 10", "line 11", "line 12", "line 14"]
    assert "data bytes" in ctx.problems.shown[4].message


def test_strict_raises_naming_file_and_line():
    with pytest.raises(InputError, match=r"bad\.asc:line 7: "):
        run(asc.read, BAD, strict=True, source="bad.asc")


def test_decimal_base_and_relative_timestamps():
    text = b"""base dec  timestamps relative
   0.5 1  256 Rx d 2 1 255
   0.25 2  100x Rx d 1 16
"""
    batch, ctx, _ = run(asc.read, text)
    assert batch.can_id.tolist() == [256, 100]
    assert batch.payload(0) == bytes([1, 255]) and batch.payload(1) == bytes([16])
    assert batch.t.tolist() == [0.5, 0.75]
    assert not ctx.absolute_time


def test_batches_are_bounded_and_keep_channel_indices():
    path = real_file("hardbyte__python-can/issue_1256.asc")
    whole, _, _ = run(asc.read, path, batch_size=100000)
    batch, _, batches = run(asc.read, path, batch_size=100)
    assert len(batches) == -(-len(whole) // 100)
    assert batch.channel.tolist() == whole.channel.tolist()
    assert batch.t.tolist() == whole.t.tolist()


def test_sniff():
    assert asc.sniff(real_file("hardbyte__python-can/logfile.asc").read_bytes()[:65536])
    assert not asc.sniff(b"(1.0) can0 123#11\n(1.1) can0 123#22\n")
    assert not asc.sniff(real_file("hilch__canopen-message-interpreter/pcan1.trc").read_bytes())
