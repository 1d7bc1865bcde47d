"""Format detection reads on past a long header or a long line (issue 37 item 1).

The first 64 KiB tell nearly every log; when no format claims them, detection reads on
(the head doubling, every format asked again) up to DETECT_BYTES or DETECT_LINES. The
frames found so must be the ones `--input-format` reads, and a file with nothing
readable is still refused in one line.
"""

from __future__ import annotations

import gzip
import subprocess
import sys

import pytest
from conftest import ROOT, real_file

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_TX, concat
from cananalyze.formats import source
from cananalyze.formats.logs import candump
from cananalyze.formats.source import open_log

# candump -L -x as can-utils prints it (see test_candump_variants.py)
CANDUMP = """\
(1784282029.600078) can0 601#4000140100000000 T
(1784282029.600912) can0 581#4300140181010000 R
(1784282029.601500) can0 701#05 R
(1784282029.604000) can0 181#0A0B T
"""


def _open(path, fmt=None):
    src = open_log(path, fmt=fmt)
    return concat(src.batches()), src


def _same(a, b):
    for col in ("t", "can_id", "flags", "dlc", "data", "line"):
        assert getattr(a, col).tolist() == getattr(b, col).tolist(), col


def _trc_v1_with(tmp_path, extra: bytes, name: str = "long.trc"):
    """python-can's PEAK TRC 1.0 file (no $FILEVERSION) with `extra` right after its header."""
    lines = real_file("hardbyte__python-can/test_CanMessage_V1_0_BUS1.trc").read_bytes()
    lines = lines.split(b"\n")
    first = next(i for i, ln in enumerate(lines) if not ln.startswith(b";"))
    p = tmp_path / name
    p.write_bytes(b"\n".join([*lines[:first], extra, *lines[first:]]))
    return p, first + 1  # the line number of `extra`


@pytest.mark.parametrize("extra", [b";" + b"-" * 70000, b"x" * 70000], ids=["comment", "junk"])
def test_trc_v1_with_a_line_over_64k_after_its_header(tmp_path, extra):
    p, at = _trc_v1_with(tmp_path, extra)
    b, src = _open(p)
    assert src.fmt.name == "trc"
    forced, _ = _open(p, "trc")
    _same(b, forced)
    # python-can's file: frames 1, 3-12 (2 is bus status), times in ms from the start
    assert len(b) == 11
    assert b.can_id.tolist()[:5] == [0x100, 0x100, 0x100, 0x0, 0x0]
    assert b.t.tolist()[:3] == pytest.approx([17.535, 17.700, 17.873])
    assert b.payload(0) == bytes(8)
    assert b.line.tolist()[0] == at + 1
    assert [p.location for p in src.problems.shown] == [f"line {at}"]
    assert "too long" in src.problems.shown[0].message
    gz = tmp_path / "long.trc.gz"
    gz.write_bytes(gzip.compress(p.read_bytes()))
    _same(_open(gz)[0], b)


def test_trc_v1_whose_header_is_longer_than_the_first_look(tmp_path):
    header = b"\n".join(
        b";   note %05d of a long PEAK header block, written by hand" % i for i in range(2000)
    )
    assert len(header) > source.SNIFF_BYTES
    p, _ = _trc_v1_with(tmp_path, header)
    b, src = _open(p)
    assert src.fmt.name == "trc" and src.problems.count == 0
    _same(b, _open(p, "trc")[0])
    assert len(b) == 11


def test_trc_v1_from_a_pipe(tmp_path):
    p, _ = _trc_v1_with(tmp_path, b"x" * 70000)
    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", "--summary", "-"],
        input=p.read_bytes(),
        capture_output=True,
        cwd=ROOT,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert b"frames: 11" in done.stdout


def test_candump_after_a_first_line_over_64k(tmp_path):
    p = tmp_path / "x.log"
    p.write_text("y" * 70000 + "\n" + CANDUMP)
    b, src = _open(p)
    assert src.fmt.name == "candump"
    assert b.can_id.tolist() == [0x601, 0x581, 0x701, 0x181]
    assert b.t.tolist() == pytest.approx(
        [1784282029.600078, 1784282029.600912, 1784282029.6015, 1784282029.604], abs=1e-7
    )
    assert [bool(f & FLAG_TX) for f in b.flags.tolist()] == [True, False, False, True]
    assert b.payload(0) == bytes.fromhex("4000140100000000")
    assert b.line.tolist() == [2, 3, 4, 5]
    assert [p.location for p in src.problems.shown] == ["line 1"]


@pytest.mark.parametrize("notes", [50, 1500], ids=["in-first-look", "past-first-look"])
def test_candump_after_a_long_header(tmp_path, notes):
    header = "".join(
        f"# {i}: ip link set can0 up type can bitrate 500000; candump -L -x can0\n"
        for i in range(notes)
    )
    assert (len(header) > source.SNIFF_BYTES) == (notes == 1500)
    p = tmp_path / "x.log"
    p.write_text(header + CANDUMP)
    b, src = _open(p)
    assert src.fmt.name == "candump"
    assert b.can_id.tolist() == [0x601, 0x581, 0x701, 0x181]
    assert b.line.tolist() == [notes + 1, notes + 2, notes + 3, notes + 4]
    assert src.problems.count == notes  # the header's lines, each skipped with a warning


def test_asc_after_a_first_line_over_64k(tmp_path):
    asc = real_file("hardbyte__python-can/logfile.asc").read_bytes()
    p = tmp_path / "x.asc"
    p.write_bytes(b"// " + b"-" * 70000 + b"\n" + asc)
    b, src = _open(p)
    assert src.fmt.name == "asc"
    plain, _ = _open(real_file("hardbyte__python-can/logfile.asc"))
    for col in ("t", "can_id", "flags", "dlc", "data"):
        assert getattr(b, col).tolist() == getattr(plain, col).tolist(), col
    assert (b.line - 1).tolist() == plain.line.tolist()
    assert len(b) == 20 and src.ctx.absolute_time


def test_candump_sniffer_wants_half_the_lines_from_the_first_frame_on():
    prose = b"".join(b"just some words on line %d of a note\n" % i for i in range(30))
    frame = b"(1784282029.600078) can0 601#4000140100000000 T\n"
    assert candump.sniff(prose + frame * 3)
    assert not candump.sniff(prose + frame + prose)  # one frame among prose
    assert candump.sniff(prose + (frame + b"a note\n") * 20)  # half the lines


def test_nothing_readable_is_still_one_line(tmp_path):
    prose = tmp_path / "notes.txt"
    prose.write_text(
        "".join(f"line {i} of a file that is not a CAN log at all\n" for i in range(50000))
    )
    with pytest.raises(InputError) as exc:
        open_log(prose)
    assert str(exc.value) == (
        f"{prose}: not a log cananalyze can read: it is text of no known CAN log format "
        "(first line: 'line 0 of a file that is not a CAN log at all')"
    )
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(256)) * (source.DETECT_BYTES // 128))  # 16 MiB, no format
    with pytest.raises(InputError, match=r"junk.bin: not a log .* binary data") as exc:
        open_log(junk)
    assert "\n" not in str(exc.value)


def test_detection_reads_only_so_far(tmp_path, monkeypatch):
    """Frames past DETECT_BYTES (or DETECT_LINES) are not looked for; --input-format reads them."""
    monkeypatch.setattr(source, "DETECT_BYTES", 256 << 10)
    near, far = tmp_path / "near.log", tmp_path / "far.log"
    near.write_text("y" * (200 << 10) + "\n" + CANDUMP)
    far.write_text("y" * (300 << 10) + "\n" + CANDUMP)
    assert _open(near)[1].fmt.name == "candump"
    with pytest.raises(InputError, match="far.log: not a log cananalyze can read"):
        open_log(far)
    assert len(_open(far, "candump")[0]) == 4
    monkeypatch.setattr(source, "DETECT_LINES", 1000)
    note = "a note, one line of a long header" + "." * 66 + "\n"  # 100 bytes
    many = tmp_path / "many.log"
    many.write_text(note * 900 + CANDUMP)  # 90 KB, past the first look
    assert _open(many)[1].fmt.name == "candump"
    many.write_text(note * 1100 + CANDUMP)  # 110 KB: under DETECT_BYTES, past DETECT_LINES
    with pytest.raises(InputError, match="many.log: not a log"):
        open_log(many)
