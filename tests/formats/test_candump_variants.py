"""candump variants read end to end: `-x` (RX/TX and the CAN FD BRS/ESI marks) and screen
lines with a bare time (issue 37 item 1).

The candump lines below are what can-utils prints: its lib.c (commit 95aae6bf) compiled
with candump.c's own print statements (candump.c lines 852-921) for eight frames, run as
`candump -ta -x`, `candump -x`, `candump -td -x`, `candump -ta` and `candump -L -x`.
"""

from __future__ import annotations

import json

import pytest

import cananalyze
from cananalyze.cli.main import main
from cananalyze.core.frames import FLAG_BRS, FLAG_ESI, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX, concat
from cananalyze.formats.source import open_log

TA_X = """\
 (1784282029.600078)  can0  TX - -  601   [8]  40 00 14 01 00 00 00 00
 (1784282029.600912)  can0  RX - -  581   [8]  43 00 14 01 81 01 00 00
 (1784282029.601500)  can0  RX - -  701   [1]  05
 (1784282029.602000)  can0  TX - -  705   [0]  remote request
 (1784282029.602750)  can0  RX B E  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB
 (1784282029.603000)  can0  TX B -  18FF0001  [08]  01 02 03 04 05 06 07 08
 (1784282029.603400)  can0  RX - -       181  [16]  00 01 02 03 04 05 06 07 08 09 0A 0B 0C 0D 0E 0F
 (1784282029.604000)  can0  TX - -       181   [2]  0A 0B
"""
X = """\
  can0  TX - -  601   [8]  40 00 14 01 00 00 00 00
  can0  RX - -  581   [8]  43 00 14 01 81 01 00 00
  can0  RX - -  701   [1]  05
  can0  TX - -  705   [0]  remote request
  can0  RX B E  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB
  can0  TX B -  18FF0001  [08]  01 02 03 04 05 06 07 08
  can0  RX - -       181  [16]  00 01 02 03 04 05 06 07 08 09 0A 0B 0C 0D 0E 0F
  can0  TX - -       181   [2]  0A 0B
"""
TD_X = """\
 (000.000000)  can0  TX - -  601   [8]  40 00 14 01 00 00 00 00
 (000.000834)  can0  RX - -  581   [8]  43 00 14 01 81 01 00 00
 (000.000588)  can0  RX - -  701   [1]  05
 (000.000500)  can0  TX - -  705   [0]  remote request
 (000.000750)  can0  RX B E  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB
 (000.000250)  can0  TX B -  18FF0001  [08]  01 02 03 04 05 06 07 08
 (000.000400)  can0  RX - -       181  [16]  00 01 02 03 04 05 06 07 08 09 0A 0B 0C 0D 0E 0F
 (000.000600)  can0  TX - -       181   [2]  0A 0B
"""
TA = """\
 (1784282029.600078)  can0  601   [8]  40 00 14 01 00 00 00 00
 (1784282029.600912)  can0  581   [8]  43 00 14 01 81 01 00 00
 (1784282029.601500)  can0  701   [1]  05
 (1784282029.602000)  can0  705   [0]  remote request
 (1784282029.602750)  can0  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB
 (1784282029.603000)  can0  18FF0001  [08]  01 02 03 04 05 06 07 08
 (1784282029.603400)  can0       181  [16]  00 01 02 03 04 05 06 07 08 09 0A 0B 0C 0D 0E 0F
 (1784282029.604000)  can0       181   [2]  0A 0B
"""
LOG_X = """\
(1784282029.600078) can0 601#4000140100000000 T
(1784282029.600912) can0 581#4300140181010000 R
(1784282029.601500) can0 701#05 R
(1784282029.602000) can0 705#R T
(1784282029.602750) can0 123##700112233445566778899AABB R
(1784282029.603000) can0 18FF0001##50102030405060708 T
(1784282029.603400) can0 181##4000102030405060708090A0B0C0D0E0F R
(1784282029.604000) can0 181#0A0B T
"""

IDS = [0x601, 0x581, 0x701, 0x705, 0x123, 0x18FF0001, 0x181, 0x181]
DATA = [
    "4000140100000000",
    "4300140181010000",
    "05",
    "",
    "00112233445566778899AABB",
    "0102030405060708",
    "000102030405060708090A0B0C0D0E0F",
    "0A0B",
]
DLC = [8, 8, 1, 0, 12, 8, 16, 2]
SENT = [True, False, False, True, False, True, False, True]
# the frames' own flags, direction aside
KIND = [0, 0, 0, FLAG_RTR, FLAG_FD | FLAG_BRS | FLAG_ESI, FLAG_EXT | FLAG_FD | FLAG_BRS, FLAG_FD, 0]
EPOCH = [
    1784282029.600078,
    1784282029.600912,
    1784282029.601500,
    1784282029.602000,
    1784282029.602750,
    1784282029.603000,
    1784282029.603400,
    1784282029.604000,
]


def _read(tmp_path, text: str, name: str = "x.log"):
    p = tmp_path / name
    p.write_text(text)
    src = open_log(p)
    b = concat(src.batches())
    return b, src


def _check_frames(b, sent, kind=KIND):
    assert b.can_id.tolist() == IDS
    assert b.dlc.tolist() == DLC
    assert [b.payload(i).hex().upper() for i in range(len(b))] == DATA
    assert [bool(f & FLAG_TX) for f in b.flags.tolist()] == sent
    assert [f & ~FLAG_TX for f in b.flags.tolist()] == kind
    assert [b.channel_name(i) for i in range(len(b))] == ["can0"] * 8
    assert b.line.tolist() == list(range(1, 9))


def test_x_with_absolute_times_keeps_direction_and_fd_marks(tmp_path):
    b, src = _read(tmp_path, TA_X)
    assert src.fmt.name == "candump" and src.problems.count == 0, src.problems.shown
    _check_frames(b, SENT)
    assert b.t.tolist() == pytest.approx(EPOCH, abs=1e-7)
    assert src.ctx.absolute_time


def test_x_without_times_and_with_delta_times(tmp_path):
    b, src = _read(tmp_path, X)
    assert src.fmt.name == "candump" and src.problems.count == 0, src.problems.shown
    _check_frames(b, SENT)
    assert b.t.tolist() == [0.0] * 8
    b, src = _read(tmp_path, TD_X)
    assert src.fmt.name == "candump" and src.problems.count == 0, src.problems.shown
    _check_frames(b, SENT)
    assert b.t[:3].tolist() == pytest.approx([0.0, 0.000834, 0.000588], abs=1e-9)
    assert not src.ctx.absolute_time


def test_screen_and_log_lines_of_one_capture_are_the_same_frames(tmp_path):
    """-ta -x and -L -x print one capture two ways: the same frames, direction and all;
    without -x there is no direction, and CAN FD is still told by its two-digit length."""
    screen, _ = _read(tmp_path, TA_X, "screen.log")
    log, src = _read(tmp_path, LOG_X, "log.log")
    assert src.problems.count == 0, src.problems.shown
    _check_frames(log, SENT)
    for col in ("t", "can_id", "flags", "dlc", "data"):
        assert getattr(screen, col).tolist() == getattr(log, col).tolist(), col
    assert [screen.payload(i) for i in range(8)] == [log.payload(i) for i in range(8)]
    plain, src = _read(tmp_path, TA, "plain.log")
    assert src.problems.count == 0, src.problems.shown
    # no -x: no direction, no BRS/ESI marks; CAN FD still from the length's two digits
    _check_frames(plain, [False] * 8, [k & ~(FLAG_BRS | FLAG_ESI) for k in KIND])
    assert plain.flags[5] == FLAG_EXT | FLAG_FD  # 18FF0001 [08]


BARE = """\
1768357807.264241 can0 601 [8] 2B 40 60 00 06 00 00 00
1768357807.265003 can0 581 [8] 60 40 60 00 00 00 00 00
1768357807.275112 can0 701 [1] 05
"""


def test_bare_epoch_times(tmp_path):
    b, src = _read(tmp_path, BARE)
    assert src.fmt.name == "candump" and src.problems.count == 0, src.problems.shown
    assert b.can_id.tolist() == [0x601, 0x581, 0x701]
    assert [b.payload(i).hex() for i in range(3)] == ["2b40600006000000", "6040600000000000", "05"]
    assert b.flags.tolist() == [0, 0, 0]
    assert b.t.tolist() == pytest.approx(
        [1768357807.264241, 1768357807.265003, 1768357807.275112], abs=1e-7
    )
    assert src.ctx.absolute_time


def test_bare_relative_times(tmp_path):
    b, src = _read(
        tmp_path,
        "0.000000 can0 601 [8] 2B 40 60 00 06 00 00 00\n"
        "0.000762 can0 581 [8] 60 40 60 00 00 00 00 00\n"
        "12.500000 can1 18FEF100 [3] 01 02 03\n",
    )
    assert src.fmt.name == "candump" and src.problems.count == 0, src.problems.shown
    assert b.can_id.tolist() == [0x601, 0x581, 0x18FEF100]
    assert b.flags.tolist() == [0, 0, FLAG_EXT]
    assert b.t.tolist() == pytest.approx([0.0, 0.000762, 12.5])
    assert [b.channel_name(i) for i in range(3)] == ["can0", "can0", "can1"]
    assert not src.ctx.absolute_time


def test_bad_lines_among_them_are_problems_of_their_line(tmp_path):
    b, src = _read(
        tmp_path,
        TA_X.splitlines(keepends=True)[0]
        + " (1784282029.600500)  can0  TX X -  601   [8]  40 00 14 01 00 00 00 00\n"
        + " (1784282029.600600)  can0  RX - -  581   [8]  43 00 14 01 81 01 00\n"
        + "1768357807.26424x can0 601 [8] 2B 40 60 00 06 00 00 00\n"
        + TA_X.splitlines(keepends=True)[1],
    )
    assert b.can_id.tolist() == [0x601, 0x581]
    assert b.line.tolist() == [1, 5]
    assert [p.location for p in src.problems.shown] == ["line 2", "line 3", "line 4"]
    assert "not a candump line" in src.problems.shown[0].message
    assert "expected 8 hex data bytes" in src.problems.shown[1].message


def test_decode_and_load_end_to_end(tmp_path, capsys):
    p = tmp_path / "x.log"
    p.write_text(TA_X + BARE.replace("1768357807.2", "1784282029.7"))
    assert main(["decode", "--format", "jsonl", str(p)]) == 0
    frames = [
        r for r in map(json.loads, capsys.readouterr().out.splitlines()) if r["kind"] == "frame"
    ]
    assert [r["can_id"] for r in frames] == IDS + [0x601, 0x581, 0x701]
    assert [r["t"] for r in frames[:2]] == [1784282029.600078, 1784282029.600912]
    assert frames[0]["data"] == "4000140100000000" and frames[0]["index"] == 0x1400
    assert frames[8]["t"] == 1784282029.764241 and frames[8]["data"] == "2b40600006000000"
    cap = cananalyze.load(p)
    f = cap.frames
    assert f["can_id"].tolist() == IDS + [0x601, 0x581, 0x701]
    assert [bool(x & FLAG_TX) for x in f["flags"].tolist()] == SENT + [False] * 3
    assert f["t"].tolist()[:8] == pytest.approx(EPOCH, abs=1e-7)
