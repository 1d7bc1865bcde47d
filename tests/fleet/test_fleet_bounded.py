"""Bounded fleet tasks (issue 39 item 2): inputs that are no regular files are refused up
front, a log that does not end is given up after --task-timeout, and a huge file that is
no log is refused without being hashed. Read back with pyarrow.dataset."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.dataset as ds
import pytest

from cananalyze.cli.main import main
from cananalyze.fleet import layout, task
from cananalyze.fleet.task import LogTask, process, run_task
from cananalyze.pipeline import Options

ROOT = Path(__file__).resolve().parents[2]
GOOD = ROOT / "samples" / "demo.log"


DATES = ds.partitioning(pa.schema([("date", pa.date32())]), flavor="hive")


def _logs(dataset: Path) -> list[dict]:
    return ds.dataset(dataset / "logs", format="parquet", partitioning=DATES).to_table().to_pylist()


def test_a_fifo_on_the_command_line_is_refused_and_the_rest_go_on(tmp_path):
    fifo = tmp_path / "never.log"
    os.mkfifo(fifo)
    dataset = tmp_path / "ds"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "cananalyze", "fleet", str(fifo), str(GOOD)]
    cmd += ["--out", str(dataset), "--workers", "1"]
    run = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 1, run.stderr  # an input left out is not a clean run
    assert f"refused: {fifo}: not a regular file (a FIFO), left out" in run.stderr
    rows = _logs(dataset)
    assert [(r["source"], r["status"]) for r in rows] == [(str(GOOD), "ok")]


def test_only_special_files_is_a_usage_error(tmp_path, capsys):
    fifo = tmp_path / "never.log"
    os.mkfifo(fifo)
    assert main(["fleet", str(fifo), "--out", str(tmp_path / "ds")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"cananalyze: error: {fifo}: not a regular file (a FIFO), left out"]
    assert main(["fleet", str(GOOD), "--out", str(tmp_path / "ds"), "--task-timeout", "0"]) == 2


def test_a_log_that_never_ends_is_given_up_after_the_timeout(tmp_path):
    """A FIFO with no writer blocks its reader for ever: run_task gives it up as a failed
    row naming the timeout; once the reader wakes, it commits nothing."""
    fifo = tmp_path / "never.log"
    os.mkfifo(fifo)
    dataset = tmp_path / "ds"
    result = run_task(LogTask(str(fifo), str(dataset), Options(checks=True), timeout=1.0))
    assert result["status"] == "failed"
    assert result["error"] == f"{fifo}: no result after 1 s (--task-timeout): given up"
    rows = _logs(dataset)
    assert [(r["source"], r["status"], r["error"]) for r in rows] == [
        (str(fifo), "failed", result["error"])
    ]
    # wake the parked reader (a writer that closes at once: an empty file), let it end
    with open(fifo, "wb"):
        pass
    deadline = time.monotonic() + 30
    while any(t.name.startswith("cananalyze-log-") for t in threading.enumerate()):
        assert time.monotonic() < deadline, "the given-up task's thread never ended"
        time.sleep(0.05)
    assert len(_logs(dataset)) == 1  # its late result was not committed
    assert not list(dataset.glob("frames/date=*/*.parquet"))
    assert not any((dataset / layout.STAGING).iterdir())


def test_a_healthy_log_is_not_affected_by_the_timeout(tmp_path):
    dataset = tmp_path / "ds"
    result = run_task(LogTask(str(GOOD), str(dataset), Options(checks=True), timeout=600))
    assert result["status"] == "ok" and result["frames"] == 185


def test_a_huge_file_that_is_no_log_is_refused_without_hashing(tmp_path, monkeypatch):
    big = tmp_path / "zeros.log"
    with open(big, "wb") as f:
        f.truncate(20 << 30)  # 20 GB of zeros, sparse: no blocks on disk
    if os.stat(big).st_blocks * 512 > 1 << 20:
        pytest.skip("this file system does not keep sparse files")
    hashed = []
    real = task.content_hash

    def counting(path, *a, **k):
        hashed.append(str(path))
        return real(path, *a, **k)

    monkeypatch.setattr(task, "content_hash", counting)
    result = process(LogTask(str(big), str(tmp_path / "ds"), Options(checks=True)))
    assert (
        result["status"] == "failed"
        and "binary data of no known CAN log format" in (result["error"])
    )
    assert str(big) not in hashed
    (row,) = _logs(tmp_path / "ds")
    assert row["status"] == "failed" and row["size"] == 20 << 30
