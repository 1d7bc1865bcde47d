"""candump reader: every variant, problems with line numbers, and python-can as a cross-check."""

from __future__ import annotations

import gzip
import io
import subprocess
import sys

import can
import numpy as np
import pytest
from conftest import ROOT, real_file

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_BRS, FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX, concat
from cananalyze.formats.logs import candump
from cananalyze.formats.source import open_log, read_all


def _read(tmp_path, text: str, strict: bool = False, name: str = "x.log"):
    p = tmp_path / name
    p.write_text(text)
    src = open_log(p, strict=strict)
    return concat(src.batches()), src


def test_log_file_format_all_frame_kinds(tmp_path):
    b, src = _read(
        tmp_path,
        "(1700000000.123456) can0 181#0102\n"
        "(1700000000.223456) can0 705#R T\n"
        "(1700000000.250000) can0 705#R3\n"
        "(1700000000.323456) can1 18FF0001#11223344 R\n"
        "(1700000000.423456) can0 20000004#0000000000000000\n"
        "(1700000000.523456) can0 123##1AABBCCDDEEFF00112233\n"
        "(1700000000.623456) can0 080#\n",
    )
    assert src.problems.count == 0
    assert src.ctx.absolute_time
    assert b.can_id.tolist() == [0x181, 0x705, 0x705, 0x18FF0001, 0x4, 0x123, 0x80]
    assert b.dlc.tolist() == [2, 0, 3, 4, 8, 10, 0]
    assert b.flags[1] == FLAG_RTR | FLAG_TX and b.flags[2] == FLAG_RTR
    assert b.flags[3] == FLAG_EXT and b.flags[4] == FLAG_ERR
    assert b.flags[5] == FLAG_FD | FLAG_BRS
    assert b.payload(5) == bytes.fromhex("AABBCCDDEEFF00112233")
    assert b.payload(0) == b"\x01\x02"
    assert [b.channel_name(i) for i in range(len(b))] == [
        "can0",
        "can0",
        "can0",
        "can1",
        "can0",
        "can0",
        "can0",
    ]
    assert b.t[0] == pytest.approx(1700000000.123456, abs=1e-7)
    assert b.line.tolist() == [1, 2, 3, 4, 5, 6, 7]


def test_screen_formats_with_and_without_times(tmp_path):
    b, src = _read(
        tmp_path,
        "candump can0\n"
        "  can0  080   [0] \n"
        "  can0  20C   [8]  00 11 22 33 44 55 66 77\n"
        "  can0  70C   [0]  remote request\n"
        "  can1  64B   [2]  00 8A           a user's comment\n"
        " (1700000000.500000)  can0  181   [2]  01 02\n"
        " (000.000123)  can0  181   [1]  03\n"
        " (2023-11-09 10:11:12.123456)  can0  18FEF100   [3]  01 02 03\n",
    )
    assert src.problems.count == 0, src.problems.shown
    assert b.can_id.tolist() == [0x80, 0x20C, 0x70C, 0x64B, 0x181, 0x181, 0x18FEF100]
    assert b.payload(1) == bytes(range(0, 0x88, 0x11))
    assert b.flags[2] & FLAG_RTR
    assert b.payload(3) == b"\x00\x8a"
    assert b.t[4] == pytest.approx(1700000000.5)
    assert b.t[5] == pytest.approx(0.000123)
    assert b.flags[6] & FLAG_EXT
    assert b.line.tolist() == [2, 3, 4, 5, 6, 7, 8]


def test_problems_are_counted_with_line_numbers_and_strict_stops(tmp_path):
    text = (
        "(1700000000.1) can0 181#0102\n"
        "(1700000000.2) can0 181#01ZZ\n"
        "garbage \x01\x02 here\n"
        "(1700000000.3) can0 1812#01\n"
        "(1700000000.4) can0 181#010\n"
        "(1700000000.5) can0 182#0304\n"
    )
    b, src = _read(tmp_path, text)
    assert b.can_id.tolist() == [0x181, 0x182]
    assert src.problems.count == 4
    assert [p.location for p in src.problems.shown] == ["line 2", "line 3", "line 4", "line 5"]
    assert "invalid hex" in src.problems.shown[0].message
    assert "odd number of hex digits" in src.problems.shown[3].message
    with pytest.raises(InputError, match=r"x.log:line 2: invalid hex"):
        _read(tmp_path, text, strict=True)


def test_bulk_and_line_parser_agree_across_chunk_boundaries(tmp_path, monkeypatch):
    """The numpy path and the line parser give the same frames; tiny chunks split lines."""
    rng = np.random.default_rng(3)
    lines = []
    for i in range(3000):
        n = int(rng.integers(0, 9))
        ident = (
            f"{int(rng.integers(0, 0x800)):03X}"
            if i % 7
            else f"{int(rng.integers(0, 1 << 29)):08X}"
        )
        data = bytes(rng.integers(0, 256, n, dtype=np.uint8)).hex().upper()
        tail = [" R", " T", ""][i % 3]
        lines.append(f"({1600000000 + i * 0.001:.6f}) can{i % 2} {ident}#{data}{tail}")
    text = "\n".join(lines) + "\n"
    fast, _ = _read(tmp_path, text)
    monkeypatch.setattr(candump, "CHUNK", 1000)
    small, _ = _read(tmp_path, text)
    expected = [candump._parse_line(ln.encode()) for ln in lines]
    for b in (fast, small):
        assert len(b) == len(lines)
        assert b.can_id.tolist() == [e[2] for e in expected]
        assert b.flags.tolist() == [e[3] for e in expected]
        assert [b.payload(i) for i in range(len(b))] == [e[4] for e in expected]
        assert np.allclose(b.t, [e[0] for e in expected], atol=1e-7, rtol=0)
        assert [b.channel_name(i) for i in range(len(b))] == [e[1].decode() for e in expected]
        assert b.line.tolist() == list(range(1, len(lines) + 1))


class _ShortReads(io.RawIOBase):
    """A stream whose readinto gives at most 7 bytes a call (a pipe, a socket)."""

    def __init__(self, data: bytes) -> None:
        self.data, self.at = data, 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = min(7, len(b), len(self.data) - self.at)
        b[:n] = self.data[self.at : self.at + n]
        self.at += n
        return n


class _NoReadinto:
    """A stream with read only (the reader falls back to bytes)."""

    def __init__(self, data: bytes) -> None:
        self.f = io.BytesIO(data)

    def read(self, n: int = -1) -> bytes:
        return self.f.read(n)


@pytest.mark.parametrize("kind", ["short_reads", "no_readinto"])
def test_chunk_buffer_streams_and_lines_longer_than_a_chunk(kind, monkeypatch):
    """The reused chunk buffer gives the frames and problems of plain bytes: short reads,
    streams without readinto, a line longer than a chunk (the carry grows in place) and
    one longer than MAX_LINE (skipped), in both the compiled and numpy paths."""
    from cananalyze.core.errors import ProblemLog
    from cananalyze.formats.registry import ReadContext

    rng = np.random.default_rng(5)
    lines = [
        f"({1600000000 + i * 0.001:.6f}) can0 {int(rng.integers(0, 0x800)):03X}#{i % 256:02X}".encode()
        for i in range(400)
    ]
    lines[50] = b"(1.5) can0 181#" + b"A" * 300  # longer than a chunk: a problem, not a frame
    lines[90] = b"B" * 900  # longer than MAX_LINE: skipped
    lines[91] = b"(1.25) can1 181#01"  # right after the skipped line
    data = b"\n".join(lines) + b"\n(2.0) can0 1FF#0102"  # the last line without newline

    def frames(stream):
        ctx = ReadContext(source="x.log", problems=ProblemLog(keep=100))
        b = concat(list(candump.read(stream, ctx)))
        return b.t.tolist(), b.can_id.tolist(), b.line.tolist(), b.data.tolist(), ctx.problems

    monkeypatch.setattr(candump, "CHUNK", 64)
    monkeypatch.setattr(candump, "MAX_LINE", 512)
    stream = _ShortReads(data) if kind == "short_reads" else _NoReadinto(data)
    t, ids, line, payload, problems = frames(stream)
    assert line == [i + 1 for i in range(len(lines) + 1) if i not in (50, 90)]
    assert ids[-1] == 0x1FF and t[line.index(92)] == 1.25
    assert problems.count == 2
    assert (t, ids, line, payload) == frames(io.BytesIO(data))[:4]


@pytest.mark.parametrize(
    "relative",
    [
        "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log",
        "collin80__SavvyCAN/candump.log",
    ],
)
def test_equal_to_python_can_on_real_logs(relative):
    path = real_file(relative)
    b = read_all(path)
    msgs = list(can.CanutilsLogReader(str(path)))
    assert len(b) == len(msgs)
    assert b.can_id.tolist() == [m.arbitration_id for m in msgs]
    assert [b.payload(i) for i in range(len(b))] == [bytes(m.data) for m in msgs]
    assert np.allclose(b.t, [m.timestamp for m in msgs], atol=1e-6, rtol=0)


@pytest.mark.parametrize(
    ("relative", "frames"),
    [
        ("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log", 16368),
        ("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log", 6375),
        ("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test3.log", 18507),
        ("jclinton830__canopen_test/candump.txt", 596),
        ("nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt", 115),
        ("RoboTrainerAID__za_experimental/candump.log", 31),
        ("SeonilChoi__CANOPEN-SDK/log2.txt", 1239),
        ("SeonilChoi__CANOPEN-SDK/log.txt", 1383),
    ],
)
def test_real_candump_logs_read_fully(relative, frames):
    src = open_log(real_file(relative))
    b = concat(src.batches())
    assert src.fmt.name == "candump"
    assert len(b) == frames  # counts from SOURCES.md
    assert src.problems.count == 0


def test_gzip_and_stdin(tmp_path):
    plain = (ROOT / "samples" / "demo.log").read_bytes()
    gz = tmp_path / "demo.log.gz"
    gz.write_bytes(gzip.compress(plain))
    assert len(read_all(gz)) == len(read_all(ROOT / "samples" / "demo.log")) == 185
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", "-", "--summary"],
        input=plain,
        capture_output=True,
        cwd=ROOT,
        check=True,
    )
    assert b"frames: 185" in out.stdout


def test_gzip_cut_short_keeps_what_was_read(tmp_path):
    plain = (ROOT / "samples" / "demo.log").read_bytes() * 200
    gz = tmp_path / "cut.log.gz"
    data = gzip.compress(plain)
    gz.write_bytes(data[: len(data) // 2])
    src = open_log(gz)
    b = concat(src.batches())
    assert 0 < len(b) < 185 * 200
    messages = [p.message for p in src.problems.shown]
    assert any("ends early" in m for m in messages)
    assert src.problems.count <= 2  # the cut, and at most the half line before it


def test_sniff_rejects_other_text():
    assert not candump.sniff(b"[FileInfo]\nFileName=x.eds\n")
    assert candump.sniff(b"(1.0) can0 181#00\n(2.0) can0 181#00\n")
    assert candump.sniff(io.BytesIO(b"  can0  181   [1]  00\n").read())
