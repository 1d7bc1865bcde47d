"""Sevcon DVT can_cli_dump reader on the four real dumps."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import real_file
from readers_util import run

from cananalyze.errors import InputError
from cananalyze.frames import FLAG_TX
from cananalyze.io import sevcon

# (file, lines counted as frames in SOURCES.md, EMCY lines with decoded text only)
DUMPS = [
    ("can_180209_154604.txt", 1397, 0),
    ("can_230309_150427.txt", 1651, 2),
    ("can_280109_111603.txt", 1399, 2),
    ("can_310309_094758.txt", 1574, 8),
]


@pytest.mark.parametrize("name,listed,emcy", DUMPS)
def test_frames_with_bytes_read_and_emcy_text_counted(name, listed, emcy):
    path = real_file(f"isPointless__Sevcon/{name}")
    batch, ctx, _ = run(sevcon.read, path, batch_size=500)
    assert len(batch) == listed - emcy
    assert ctx.problems.count == emcy
    assert all("EMCY" in p.message for p in ctx.problems.shown)
    assert np.all(np.diff(batch.t) >= 0)  # Tx frames logged at time 0 are put in order
    assert sevcon.sniff(path.read_bytes())


def test_known_rows():
    batch, ctx, _ = run(sevcon.read, real_file("isPointless__Sevcon/can_230309_150427.txt"))
    # "0x0080   547216 - d19.3 0 SYNC" then "0x0183   547227  - d14.0 0 Unknown { 0xD6 ... }"
    assert batch.can_id[:2].tolist() == [0x80, 0x183]
    assert batch.dlc[0] == 0 and batch.t[0] == pytest.approx(54.7216)
    assert batch.payload(1) == bytes.fromhex("D604DA04FEFC30FD")
    assert batch.line[:2].tolist() == [1, 2]
    assert [p.location for p in ctx.problems.shown] == ["line 270", "line 302"]
    tx = batch.flags & FLAG_TX != 0
    assert tx.sum() == 9 and set(batch.can_id[tx].tolist()) <= {0x601, 0x000}


BAD = b"""0x0080   547216 - d19.3 0 SYNC
0x0183   547227  - d14.0 0 Unknown { 0xD6 0xZZ }
hello
0x0183   547230  - d14.0 0 Unknown { 0xD6 0x01
0x0183   547240  - d14.0 0 Unknown { 0x01 0x02 }
"""


def test_bad_lines():
    batch, ctx, _ = run(sevcon.read, BAD, source="d.txt")
    assert batch.line.tolist() == [1, 5]
    assert [p.location for p in ctx.problems.shown] == ["line 2", "line 3", "line 4"]
    with pytest.raises(InputError, match=r"d\.txt:line 2: invalid data bytes"):
        run(sevcon.read, BAD, strict=True, source="d.txt")
