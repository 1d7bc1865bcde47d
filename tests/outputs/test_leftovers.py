"""A run killed with SIGKILL leaves its temporary files; the next run in that folder on this
machine removes them (issue 38): they carry the machine and the process that wrote them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pyarrow.parquet as pq
import pytest
from conftest import SAMPLES, generated_log

from cananalyze.core import atomic


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def _export(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", *args, "-q"],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_the_next_export_removes_what_a_killed_one_left(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        dead = out / f".frames.cananalyze-{atomic._HOST}-{_dead_pid()}-k3j2.parquet"
        running = out / f".sdo.cananalyze-{atomic._HOST}-{alive.pid}-x9a1.parquet"
        other_host = out / f".frames.cananalyze-00000000-{_dead_pid()}-q1w2.parquet"
        mine = out / "notes.parquet"  # not ours: never touched
        for p in (dead, running, other_host, mine):
            p.write_bytes(b"PAR1 half written")
        r = _export(str(SAMPLES / "demo.log"), "--parquet", str(out))
        assert r.returncode == 0, r.stderr
        assert not dead.exists()
        assert running.exists() and other_host.exists() and mine.exists()
        assert pq.read_table(out / "frames.parquet").num_rows == 185
    finally:
        alive.kill()
        alive.wait()


@pytest.mark.slow
def test_kill_9_mid_export_then_a_rerun_leaves_nothing(tmp_path):
    log = generated_log(tmp_path, 2_000_000)
    out = tmp_path / "out"
    out.mkdir()
    p = subprocess.Popen(
        [sys.executable, "-m", "cananalyze", "export", str(log), "--parquet", str(out), "-q"]
    )
    try:
        deadline = time.monotonic() + 120  # a bound against a hang, not a measurement
        while not any(".cananalyze-" in f.name for f in out.iterdir()):
            assert p.poll() is None, "the export ended before writing"
            assert time.monotonic() < deadline
            time.sleep(0.05)
        os.kill(p.pid, signal.SIGKILL)
    finally:
        p.wait()
    left = [f for f in out.iterdir() if ".cananalyze-" in f.name]
    assert left and not (out / "frames.parquet").exists()  # killed: nothing committed
    r = _export(str(SAMPLES / "demo.log"), "--parquet", str(out))
    assert r.returncode == 0, r.stderr
    assert not [f for f in out.iterdir() if f.name.startswith(".")]
    assert pq.read_table(out / "frames.parquet").num_rows == 185
