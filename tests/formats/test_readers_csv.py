"""GVRET (SavvyCAN) CSV and python-can CSV readers."""

from __future__ import annotations

import random

import can
import numpy as np
import pandas as pd
import pytest
from conftest import real_file
from readers_util import assert_same_as_python_can, run

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_EXT, FLAG_TX
from cananalyze.formats.logs import gvret, pycan_csv

GVRET = "collin80__SavvyCAN/GVRET_Log.csv"


def test_gvret_every_row_equals_an_independent_pandas_parse():
    path = real_file(GVRET)
    batch, ctx, batches = run(gvret.read, path, batch_size=5000)
    df = pd.read_csv(path, index_col=False, dtype=str)
    assert len(batch) == len(df) == 12974 and len(batches) == 3
    assert ctx.problems.count == 0 and not ctx.absolute_time
    assert np.allclose(batch.t, df["Time Stamp"].astype(np.int64) / 1e6)
    assert batch.can_id.tolist() == [int(x, 16) for x in df["ID"]]
    assert batch.dlc.tolist() == df["LEN"].astype(int).tolist()
    cols = [f"D{i}" for i in range(1, 9)]
    full = np.array([[int(x, 16) for x in row] for row in df[cols].itertuples(index=False)])
    mask = np.arange(8)[None, :] < batch.dlc[:, None]
    assert np.array_equal(batch.data, np.where(mask, full, 0))
    assert batch.line.tolist() == list(range(2, 12976))
    assert batch.channels == ("0",)


GVRET_BAD = b"""Time Stamp,ID,Extended,Dir,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8
1000,0000021A,false,Rx,0,2,FE,36,
2000,0000021G,false,Rx,0,2,FE,36,
3000,18FF0001,true,Tx,1,1,AA,
4000,0000021A,false,Rx,0,3,FE,36
5000,0000021A,maybe,Rx,0,1,FE
6000,0000021A,false,Rx,0,1,XZ
7000,0000021A,false
"""


def test_gvret_bad_rows_counted_with_dir_column():
    batch, ctx, _ = run(gvret.read, GVRET_BAD, source="g.csv")
    assert batch.can_id.tolist() == [0x21A, 0x18FF0001]
    assert batch.flags.tolist() == [0, FLAG_EXT | FLAG_TX]
    assert batch.line.tolist() == [2, 4]
    assert [batch.channel_name(i) for i in range(2)] == ["0", "1"]
    assert [p.location for p in ctx.problems.shown] == [f"line {n}" for n in (3, 5, 6, 7, 8)]
    with pytest.raises(InputError, match=r"g\.csv:line 3: invalid identifier"):
        run(gvret.read, GVRET_BAD, strict=True, source="g.csv")


def _messages():
    rnd = random.Random(3)
    out = []
    for i in range(3000):
        ext = i % 7 == 0
        out.append(
            can.Message(
                timestamp=1700000000.0 + i / 997,
                arbitration_id=rnd.randrange(0x20000000 if ext else 0x800),
                is_extended_id=ext,
                is_remote_frame=i % 50 == 1,
                is_error_frame=i % 400 == 3,
                dlc=3 if i % 50 == 1 else None,
                data=b""
                if i % 50 == 1
                else bytes(rnd.randrange(256) for _ in range(rnd.randrange(9))),
            )
        )
    return out


def test_pycan_csv_matches_python_can(tmp_path):
    path = tmp_path / "log.csv"
    with can.CSVWriter(str(path)) as w:
        for m in _messages():
            w.on_message_received(m)
    batch, ctx, _ = run(pycan_csv.read, path, batch_size=1000)
    expected = list(can.CSVReader(str(path)))
    assert len(expected) == 3000
    assert_same_as_python_can(batch, expected, channel_offset=None)
    assert ctx.absolute_time and ctx.start_time == 1700000000.0
    assert pycan_csv.sniff(path.read_bytes()) and not gvret.sniff(path.read_bytes())


def test_pycan_csv_bad_lines():
    text = b"""timestamp,arbitration_id,extended,remote,error,dlc,data
1.5,0x123,0,0,0,2,AQI=
1.6,0x12Z,0,0,0,2,AQI=
1.7,0x124,0,0,0,2,A!I=
1.8,0x800,0,0,0,0,
1.9,0x125,2,0,0,0,
2.0,0x126,0,0,0
2.1,0x127,1,0,0,1,/w==
"""
    batch, ctx, _ = run(pycan_csv.read, text, source="p.csv")
    assert batch.can_id.tolist() == [0x123, 0x127]
    assert batch.payload(0) == b"\x01\x02" and batch.payload(1) == b"\xff"
    assert [p.location for p in ctx.problems.shown] == [f"line {n}" for n in (3, 4, 5, 6, 7)]
    assert not ctx.absolute_time
    with pytest.raises(InputError, match=r"p\.csv:line 3: "):
        run(pycan_csv.read, text, strict=True, source="p.csv")


def test_pycan_csv_blank_lines_read_the_frames_python_can_reads(tmp_path):
    """Issue 38 item 5: 150,000 blank lines (empty, CRLF, spaces) among 3000 frames are
    skipped in bulk; python-can's CSVReader, which has no blank lines, reads the same
    frames from the file without them, and each frame keeps the line it is on."""
    plain = tmp_path / "plain.csv"
    with can.CSVWriter(str(plain)) as w:
        for m in _messages():
            w.on_message_received(m)
    rows = plain.read_bytes().splitlines(keepends=True)
    blanks = [b"\n" * 200, b"\r\n", b" \t \n", b"\n"]
    text = rows[0] + b"".join(r + blanks[i % 4] for i, r in enumerate(rows[1:]))
    path = tmp_path / "blank.csv"
    path.write_bytes(text)
    batch, ctx, _ = run(pycan_csv.read, path, batch_size=1000)
    assert ctx.problems.count == 0
    assert_same_as_python_can(batch, list(can.CSVReader(str(plain))), channel_offset=None)
    lines = text.split(b"\n")
    assert text.count(b"\n") > 150_000
    assert [lines[k - 1] for k in batch.line.tolist()] == [r.rstrip(b"\r\n") for r in rows[1:]]


def test_pycan_csv_header_is_line_one():
    """A blank first line is no header (as before blank lines were skipped in bulk)."""
    header = b"timestamp,arbitration_id,extended,remote,error,dlc,data\n"
    batch, ctx, _ = run(pycan_csv.read, b"\n" + header + b"1.5,0x123,0,0,0,2,AQI=\n")
    assert len(batch) == 0
    assert [(p.location, p.message) for p in ctx.problems.shown] == [
        ("line 1", "not a python-can CSV header")
    ]
    batch, ctx, _ = run(pycan_csv.read, header + b"\n \n1.5,0x123,0,0,0,2,AQI=\n")
    assert batch.line.tolist() == [4] and ctx.problems.count == 0
