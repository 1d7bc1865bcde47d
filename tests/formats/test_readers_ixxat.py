"""IXXAT MiniMon ASCII trace reader, cross-checked against the third-party decode CSV."""

from __future__ import annotations

import datetime

import pytest
from conftest import real_file
from readers_util import run

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_EXT, FLAG_RTR
from cananalyze.formats.logs import ixxat

TRACE = "hilch__canopen-message-interpreter/ixxat1.trc"


def _oracle():
    """(time ms, id, dlc, data) of every row of the repo's own decode of ixxat1.trc."""
    rows = []
    lines = real_file(TRACE + ".csv").read_text(encoding="latin-1").splitlines()[1:]
    for line in lines:
        f = line.split(";")
        data = bytes(int(x, 16) for x in f[4].strip("[]").split()) if f[4] else b""
        rows.append((float(f[1].replace(",", ".")), int(f[2], 16), int(f[3]), data))
    return rows


def test_every_row_matches_the_third_party_decode():
    batch, ctx, _ = run(ixxat.read, real_file(TRACE), batch_size=100)
    oracle = _oracle()
    assert len(batch) == len(oracle) == 781  # SOURCES.md
    assert ctx.problems.count == 0 and ctx.format == "ixxat"
    start = datetime.datetime(2025, 1, 28, 10, 47, 15).timestamp()  # the header, local time
    for i, (ms, can_id, dlc, data) in enumerate(oracle):
        assert (batch.t[i] - start) * 1000 == pytest.approx(ms - oracle[0][0], abs=1e-3), i
        assert batch.can_id[i] == can_id, i
        assert batch.dlc[i] == dlc, i
        if not batch.flags[i] & FLAG_RTR:
            assert batch.payload(i) == data, i
    assert int((batch.flags & FLAG_RTR != 0).sum()) == 40
    assert batch.line[0] == 8 and batch.line[-1] == 788
    assert datetime.datetime.fromtimestamp(ctx.start_time) == datetime.datetime(
        2025, 1, 28, 10, 47, 15
    )
    assert ctx.absolute_time and batch.t[0] == start  # issue 24: the header's start is used


BAD = b"""ASCII Trace IXXAT MiniMon V3  Version: 1.0.0.1271
Date: 28.01.2025
Start time: 10:47:15
"Time";"Identifier (hex)";"Format";"Flags";"Data (hex)"
"00:02:20.66";"83";"Std";"";"00 00 00 01 "
"00:02:20.67";"8G";"Std";"";"00 "
"00:02:20.68";"1ABCDEF0";"Ext";"";"11 22 "
"00:0x:20.69";"703";"Std";"";"7F "
"00:02:20.70";"703";"Std";"";"7F 0"
"00:02:20.71";"703";"Std"
"00:02:20.72";"702";"Std";"Rtr ";"Remote request  DLC = 1 "
"00:02:20.73";"800";"Std";"";"7F "
"""


def test_bad_rows_are_skipped_and_counted():
    batch, ctx, _ = run(ixxat.read, BAD, source="bad.trc")
    assert batch.can_id.tolist() == [0x83, 0x1ABCDEF0, 0x702]
    assert batch.flags.tolist() == [0, FLAG_EXT, FLAG_RTR]
    assert batch.line.tolist() == [5, 7, 11]
    assert [p.location for p in ctx.problems.shown] == [
        "line 6",
        "line 8",
        "line 9",
        "line 10",
        "line 12",
    ]
    with pytest.raises(InputError, match=r"bad\.trc:line 6: invalid identifier"):
        run(ixxat.read, BAD, strict=True, source="bad.trc")


def test_sniff():
    assert ixxat.sniff(real_file(TRACE).read_bytes())
    assert not ixxat.sniff(real_file("hilch__canopen-message-interpreter/pcan1.trc").read_bytes())
