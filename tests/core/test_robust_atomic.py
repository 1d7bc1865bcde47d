"""Atomic outputs: an interrupted export leaves the old file or none, never half a file."""

from __future__ import annotations

import os
import stat

import pytest

from cananalyze.cli.main import main
from cananalyze.core.atomic import atomic_path, atomic_write
from cananalyze.core.frames import from_rows
from cananalyze.formats import logfile
from cananalyze.formats.logs import _pycan_writer, candump
from cananalyze.formats.source import read_all

SAMPLE = os.path.join(os.path.dirname(__file__), "..", "..", "samples", "demo.log")


def _leftovers(d):
    return sorted(p.name for p in d.iterdir() if p.name.startswith("."))


def test_atomic_write_replaces_only_on_success(tmp_path):
    target = tmp_path / "out.jsonl"
    target.write_text("old\n")
    with pytest.raises(RuntimeError), atomic_write(target) as f:
        f.write("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "old\n" and _leftovers(tmp_path) == []
    with atomic_write(target) as f:
        f.write("new\n")
        assert target.read_text() == "old\n"  # not visible before the end
    assert target.read_text() == "new\n" and _leftovers(tmp_path) == []


def test_new_file_gets_ordinary_permissions_and_old_mode_is_kept(tmp_path):
    old = os.umask(0o022)
    try:
        with atomic_write(tmp_path / "a.txt") as f:
            f.write("x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o644
    b = tmp_path / "b.txt"
    b.write_text("x")
    b.chmod(0o600)
    with atomic_write(b, "wb") as f:
        f.write(b"y")
    assert stat.S_IMODE(b.stat().st_mode) == 0o600 and b.read_bytes() == b"y"


def test_atomic_path_keeps_compound_suffix_and_devices_are_written_directly(tmp_path):
    with atomic_path(tmp_path / "x.log.gz") as tmp:
        assert tmp.name.endswith(".log.gz") and tmp.parent == tmp_path
        tmp.write_bytes(b"")
    with atomic_write(os.devnull) as f:  # renaming over /dev/null would replace the device
        f.write("discarded")
    assert stat.S_ISCHR(os.stat(os.devnull).st_mode)


def test_decode_output_interrupted_leaves_no_file(tmp_path, monkeypatch, capsys):
    out = tmp_path / "decoded.txt"
    from cananalyze.pipeline import Decoder

    real = Decoder.decode
    calls = []

    def interrupted(self, batch):
        calls.append(1)
        if len(calls) > 1:
            raise KeyboardInterrupt
        return real(self, batch)

    monkeypatch.setattr(Decoder, "decode", interrupted)
    log = tmp_path / "big.log"
    log.write_text("".join(f"({i / 1000:.6f}) can0 181#{i % 256:02X}\n" for i in range(70000)))
    assert main(["decode", str(log), "-o", str(out)]) == 130
    assert not out.exists() and _leftovers(tmp_path) == []
    monkeypatch.setattr(Decoder, "decode", real)
    assert main(["decode", str(log), "--format", "jsonl", "-o", str(out)]) == 0
    assert out.read_text().count("\n") == 70000


def test_decode_strict_failure_leaves_previous_output(tmp_path, capsys):
    out = tmp_path / "decoded.jsonl"
    out.write_text("previous\n")
    log = tmp_path / "bad.log"
    log.write_text("(1.0) can0 181#01\n(2.0) can0 181#XY\n")
    assert main(["decode", "--strict", str(log), "-o", str(out)]) == 2
    assert out.read_text() == "previous\n" and _leftovers(tmp_path) == []


def test_decode_output_in_missing_directory_is_one_line(tmp_path, capsys):
    rc = main(["decode", SAMPLE, "-o", str(tmp_path / "nodir" / "x.txt")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "does not exist" in err


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_write_log_is_atomic(suffix, tmp_path, monkeypatch):
    batch = from_rows([(1.0, 0x181, b"\x01\x02"), (2.0, 0x701, b"\x05")])
    target = tmp_path / f"x{suffix}"
    logfile.write_log(batch, target)
    first = target.read_bytes()
    assert len(read_all(target)) == 2

    def broken(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(candump, "candump_bytes", broken)
    monkeypatch.setattr(_pycan_writer, "to_messages", broken)
    with pytest.raises(OSError):
        logfile.write_log(batch, target)
    assert target.read_bytes() == first and _leftovers(tmp_path) == []
