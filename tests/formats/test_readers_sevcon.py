"""Sevcon DVT can_cli_dump reader on the four real dumps."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from conftest import real_file
from readers_util import run

from cananalyze.cli.main import main
from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_RECONSTRUCTED, FLAG_TX, RECONSTRUCTED_MARK
from cananalyze.formats.logs import sevcon

# (file, lines counted as frames in SOURCES.md, EMCY lines with decoded text only)
DUMPS = [
    ("can_180209_154604.txt", 1397, 0),
    ("can_230309_150427.txt", 1651, 2),
    ("can_280109_111603.txt", 1399, 2),
    ("can_310309_094758.txt", 1574, 8),
]


@pytest.mark.parametrize("name,listed,emcy", DUMPS)
def test_every_line_read_emcy_text_rebuilt(name, listed, emcy):
    path = real_file(f"isPointless__Sevcon/{name}")
    batch, ctx, _ = run(sevcon.read, path, batch_size=500)
    assert len(batch) == listed  # issue 24: the EMCY lines are frames too
    assert ctx.problems.count == 0
    emcys = [line for line in path.read_text(encoding="latin-1").splitlines() if " EMCY " in line]
    assert len(emcys) == emcy
    rows = np.flatnonzero(batch.can_id == 0x81)
    assert len(rows) == emcy
    for r, line in zip(rows, emcys, strict=True):  # the Sevcon code in bytes 3-4
        code = int(line.rsplit("0x", 1)[1], 16)
        assert batch.payload(int(r))[3:5] == code.to_bytes(2, "little")
    assert np.all(np.diff(batch.t) >= 0)  # Tx frames logged at time 0 are put in order
    assert sevcon.sniff(path.read_bytes())


def test_known_rows():
    batch, ctx, _ = run(sevcon.read, real_file("isPointless__Sevcon/can_230309_150427.txt"))
    # "0x0080   547216 - d19.3 0 SYNC" then "0x0183   547227  - d14.0 0 Unknown { 0xD6 ... }"
    assert batch.can_id[:2].tolist() == [0x80, 0x183]
    assert batch.dlc[0] == 0 and batch.t[0] == pytest.approx(54.7216)
    assert batch.payload(1) == bytes.fromhex("D604DA04FEFC30FD")
    assert batch.line[:2].tolist() == [1, 2]
    assert ctx.problems.count == 0
    emcy = batch.take(batch.can_id == 0x81)  # line 270: "EMCY Error Reset or No Error. Sevcon
    assert emcy.line.tolist() == [270, 302]  # code: 0x45C4", then 0x45C5
    assert emcy.payload(0) == bytes.fromhex("000000C445000000")
    assert emcy.payload(1) == bytes.fromhex("000000C545000000")
    tx = batch.flags & FLAG_TX != 0
    assert tx.sum() == 9 and set(batch.can_id[tx].tolist()) <= {0x601, 0x000}


@pytest.mark.parametrize("name,listed,emcy", DUMPS)
def test_rebuilt_emcy_frames_and_only_they_are_marked(name, listed, emcy, capsys):
    """Issue 44 item 13: bytes rebuilt from DVT's text are not shown as captured. The
    reader flags the EMCY frames it rebuilt (every one: no other frame lacks bytes), and
    text and JSONL mark exactly those."""
    path = real_file(f"isPointless__Sevcon/{name}")
    batch, _, _ = run(sevcon.read, path)
    rebuilt = (batch.flags & FLAG_RECONSTRUCTED) != 0
    assert rebuilt.sum() == emcy
    assert np.array_equal(rebuilt, batch.can_id == 0x81)
    lines = batch.line[rebuilt].tolist()
    text = path.read_text(encoding="latin-1").splitlines()
    assert all(" EMCY " in text[n - 1] and "{" not in text[n - 1] for n in lines)

    assert main(["decode", str(path), "--no-color"]) == 0
    lines_out = capsys.readouterr().out.splitlines()
    frame_line = re.compile(r"^\s*-?\d+\.\d{6}  \S+\s+[0-9A-F]{3,8}  \[\d\]  ")
    out = [line for line in lines_out if frame_line.match(line)]
    assert len(out) == listed
    others = [line for line in lines_out if not frame_line.match(line)]  # SDO records
    assert not any(RECONSTRUCTED_MARK in line for line in others)
    marked = [i for i, line in enumerate(out) if RECONSTRUCTED_MARK in line]
    assert marked == np.flatnonzero(rebuilt).tolist()
    for i in marked:  # the mark just before the annotation, after the captured columns
        assert f"emcy             1  {RECONSTRUCTED_MARK} EMCY" in out[i]

    assert main(["decode", str(path), "--format", "jsonl"]) == 0
    recs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    frames = [r for r in recs if r["kind"] == "frame"]
    assert len(frames) == listed
    flagged = [i for i, r in enumerate(frames) if "reconstructed" in r]
    assert flagged == np.flatnonzero(rebuilt).tolist()
    assert all(
        frames[i]["reconstructed"] is True and frames[i]["service"] == "emcy" for i in flagged
    )


BAD = b"""0x0080   547216 - d19.3 0 SYNC
0x0183   547227  - d14.0 0 Unknown { 0xD6 0xZZ }
hello
0x0183   547230  - d14.0 0 Unknown { 0xD6 0x01
0x0183   547240  - d14.0 0 Unknown { 0x01 0x02 }
"""


def test_emcy_text_becomes_the_frame_it_describes():
    text = (
        b"0x0081   100 - d1.0 0 EMCY Mains Voltage. Sevcon code: 0x45C5\n"
        b"0x0081   200 - d1.0 0 EMCY Device specific. Sevcon code: 0x4883\n"
        b"0x0081   300 - d1.0 0 EMCY Error Reset or No Error. Sevcon code: 0x4883\n"
        b"0x0081   400 - d1.0 0 EMCY Flux capacitor. Sevcon code: 0x4883\n"
        b"0x0081   500 - d1.0 0 EMCY Mains Voltage. no code\n"
    )
    batch, ctx, _ = run(sevcon.read, text, source="e.txt")
    assert [batch.payload(i).hex() for i in range(len(batch))] == [
        "003101c545000000",  # 0x3100 mains voltage, register: generic error
        "00ff018348000000",
        "0000008348000000",  # error reset: register clear
    ]
    assert [p.location for p in ctx.problems.shown] == ["line 4", "line 5"]


def test_bad_lines():
    batch, ctx, _ = run(sevcon.read, BAD, source="d.txt")
    assert batch.line.tolist() == [1, 5]
    assert [p.location for p in ctx.problems.shown] == ["line 2", "line 3", "line 4"]
    with pytest.raises(InputError, match=r"d\.txt:line 2: invalid data bytes"):
        run(sevcon.read, BAD, strict=True, source="d.txt")
