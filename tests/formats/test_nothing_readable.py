"""A file of which nothing can be read is a failure, not "0 frames" (issue 38): exit 2
with its first problem named; a corrupt gzip says so, with the offset; a gzip cut off
in the middle of a line gives the frames before it and no frame made of half a line."""

from __future__ import annotations

import gzip
import io
import os
import subprocess
import sys
import zlib

import can
import pytest

from cananalyze.core.errors import InputError
from cananalyze.formats.source import read_all


def _cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
    )


def _one_error(stderr: str) -> str:
    errors = [line for line in stderr.splitlines() if line.startswith("cananalyze: error:")]
    assert len(errors) == 1 and "Traceback" not in stderr, stderr
    return errors[0]


def test_blf_signature_then_random_bytes_fails(tmp_path):
    path = tmp_path / "r.blf"
    path.write_bytes(b"LOGG" + os.urandom(3000))
    for cmd in (["decode", str(path)], ["check", str(path)]):
        out = _cli(*cmd)
        assert out.returncode == 2, out
        line = _one_error(out.stderr)
        assert str(path) in line and "no frame could be read" in line
    out = _cli("export", str(path), "--parquet", str(tmp_path / "out"))
    assert out.returncode == 2 and not (tmp_path / "out").exists()
    with pytest.raises(InputError, match="no frame could be read"):
        read_all(path)


def test_an_empty_log_is_not_a_failure(tmp_path):
    """python-can's BLF with no message: a log with no frames, nothing wrong with it."""
    path = tmp_path / "empty.blf"
    with can.BLFWriter(str(path)):
        pass
    assert list(can.BLFReader(str(path))) == []
    out = _cli("decode", str(path))
    assert out.returncode == 0 and "error" not in out.stderr
    assert len(read_all(path)) == 0


def test_corrupt_gzip_says_corrupt_gzip_with_the_offset(tmp_path):
    path = tmp_path / "c.log.gz"
    path.write_bytes(b"\x1f\x8b\x08\x00" + bytes(range(7, 256)) * 2)
    out = _cli("decode", str(path))
    assert out.returncode == 2
    line = _one_error(out.stderr)
    assert f"{path}: corrupt gzip at or before compressed byte" in line
    assert "empty" not in line


def _candump_text(n: int = 400) -> bytes:
    """n frames as python-can's candump writer prints them."""
    buf = io.StringIO()
    w = can.CanutilsLogWriter(buf, channel="can0")
    for i in range(n):
        w.on_message_received(
            can.Message(
                timestamp=1_700_000_000 + i * 0.01,
                arbitration_id=0x181 + i % 8,
                data=bytes([i % 256, 1, 2, 3, 4, 5, 6, 7]),
                is_extended_id=False,
            )
        )
    return buf.getvalue().encode()


def test_gzip_cut_in_a_line_keeps_what_came_before_and_invents_nothing(tmp_path):
    text = _candump_text()
    packed = gzip.compress(text, compresslevel=9)
    cut = packed[: len(packed) * 2 // 3]
    path = tmp_path / "cut.log.gz"
    path.write_bytes(cut)
    # what zlib itself gets out of the cut stream, and the complete lines in it
    prefix = zlib.decompressobj(wbits=31).decompress(cut)
    assert prefix and not prefix.endswith(b"\n")  # the cut falls inside a line
    whole = prefix[: prefix.rfind(b"\n") + 1]
    (tmp_path / "whole.log").write_bytes(whole)
    want = list(can.CanutilsLogReader(str(tmp_path / "whole.log")))
    fb = read_all(path)
    assert len(fb) == len(want) > 0
    assert [int(c) for c in fb.can_id] == [m.arbitration_id for m in want]
    assert [fb.payload(i) for i in range(len(fb))] == [bytes(m.data) for m in want]
    out = _cli("decode", str(path))
    assert out.returncode == 0  # lenient: the frames before the cut, and a warning
    assert "corrupt gzip at or before compressed byte" in out.stderr
    assert "an incomplete line, left out" in out.stderr
    # the whole file still reads whole (nothing held back when the stream ends well)
    path.write_bytes(packed)
    assert len(read_all(path)) == len(list(can.CanutilsLogReader(io.StringIO(text.decode()))))
