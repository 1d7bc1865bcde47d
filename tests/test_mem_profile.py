"""benchmarks/mem_profile.py runs a command and reports its memory over time."""

from __future__ import annotations

import ctypes
import subprocess
import sys

import pyarrow.parquet as pq
from conftest import ROOT, SAMPLES


def test_mem_profile_runs_the_command_and_reports_peaks(tmp_path):
    out = tmp_path / "pq"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "mem_profile.py"),
            "--every",
            "0.01",
            "export",
            str(SAMPLES / "faults.log"),
            "--parquet",
            str(out),
            "-q",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    assert pq.read_table(out / "frames.parquet").num_rows > 0  # the command itself ran
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("peak RSS ")
    peak = int(last.split()[2])
    assert 20 < peak < 2000
    if sys.platform.startswith("linux") and hasattr(ctypes.CDLL(None), "mallinfo2"):
        assert "malloc in use: max" in last  # glibc 2.33+


def test_arrow_column_waits_for_a_whole_pyarrow(monkeypatch):
    """The sampler runs while the CLI imports pyarrow: a module without its functions yet
    is no figure, not an error that stops the sampling (it did, on a 50M-frame run)."""
    import types

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import mem_profile
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    monkeypatch.setitem(sys.modules, "pyarrow", types.ModuleType("pyarrow"))  # mid-import
    assert mem_profile._arrow_mb() is None
    monkeypatch.delitem(sys.modules, "pyarrow")
    assert mem_profile._arrow_mb() is None
    whole = types.ModuleType("pyarrow")
    whole.total_allocated_bytes = lambda: 5 << 20
    monkeypatch.setitem(sys.modules, "pyarrow", whole)
    assert mem_profile._arrow_mb() == 5
