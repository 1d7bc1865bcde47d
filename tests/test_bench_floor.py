"""benchmarks/bench_floor.py measures the library-only CPU of an export and prints the floor."""

from __future__ import annotations

import subprocess
import sys

from conftest import ROOT


def test_floor_table_for_every_format(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "bench_floor.py"),
            "--size",
            "3000",
            "--repeat",
            "1",
            "--out",
            str(tmp_path),
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    lines = done.stdout.splitlines()
    assert any(line.startswith("  Parquet encoding of the exported tables:") for line in lines)
    rows = {line.split()[0]: line.split() for line in lines if line[:1] == "."}
    assert set(rows) == {".log", ".blf", ".asc"}
    for cells in rows.values():
        read, total, floor = float(cells[1]), float(cells[2]), float(cells[3].rstrip("s"))
        assert 0 <= read < total and abs(floor - total / 2) < 0.01
    assert not list(tmp_path.glob("tmp*"))  # the exported tables are cleaned up
