"""Shared test fixtures: where the real data lives, skipping cleanly when it is absent."""

from __future__ import annotations

import atexit
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

# device files' parsed facts (devices/od_facts.py) cached in a folder of the run's own, not
# the user's ~/.cache; inherited by the commands the tests start
if "CANANALYZE_CACHE" not in os.environ:
    os.environ["CANANALYZE_CACHE"] = tempfile.mkdtemp(prefix="cananalyze-test-cache-")
    atexit.register(shutil.rmtree, os.environ["CANANALYZE_CACHE"], True)

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
REAL = SHARED / "data" / "real"
SEEDS = SHARED / "seeds"
SAMPLES = ROOT / "samples"


def generated_log(directory: Path, frames: int, faults: bool = True) -> Path:
    """A candump log of `frames` frames from the benchmark generator (16 nodes, PDOs,
    SDO, EMCY), written as the benchmarks write theirs; `faults`: its faulty bus, which
    breaks a rule every few frames (every findings path), else the healthy one."""
    stem = directory / "g"
    extra = ["--faults"] if faults else []
    subprocess.run(
        [
            sys.executable,
            str(ROOT / "benchmarks" / "generate.py"),
            str(frames),
            str(stem),
            ".log",
            *extra,
        ],
        check=True,
        capture_output=True,
    )
    return stem.with_suffix(".log")


def real_file(relative: str) -> Path:
    """Path of a file under ../shared/data/real, or skip the test if it is not there."""
    path = REAL / relative
    if not path.exists():
        pytest.skip(f"real data not available: {path}")
    return path


def seed_file(name: str) -> Path:
    path = SEEDS / name
    if not path.exists():
        pytest.skip(f"seed manual not available: {path}")
    return path


@pytest.fixture
def cluster():
    """A Dask cluster in this process (threads), for the fleet tests: what the workers call can be watched."""
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        protocol="tcp://",
        host="127.0.0.1",
        dashboard_address=None,
    ) as c:
        yield c.scheduler_address
