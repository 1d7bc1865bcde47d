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
