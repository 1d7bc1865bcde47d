"""`cananalyze live` in a child process reading an slcan adapter simulated on a pty."""

from __future__ import annotations

import os
import pty
import subprocess
import sys
import tty
from pathlib import Path

import pytest

from cananalyze.sim.slcan_replay import SlcanAdapter

ROOT = Path(__file__).resolve().parents[2]


def start_live(
    args: list[str], cwd: Path = ROOT, stdout=subprocess.PIPE
) -> tuple[subprocess.Popen, SlcanAdapter, int]:
    """Start `cananalyze live -i slcan` on a fresh pty; returns (process, adapter, slave fd).
    `stdout`: a pipe (default) or an open file."""
    master, slave = pty.openpty()
    tty.setraw(slave)
    env = dict(os.environ, PYTHONPATH=str(ROOT), TERM="dumb")
    cmd = [sys.executable, "-m", "cananalyze", "live", "-i", "slcan", "-c", os.ttyname(slave)]
    proc = subprocess.Popen(
        [*cmd, "-b", "500000", *args],
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=cwd,
    )
    adapter = SlcanAdapter(master)
    if not adapter.wait_open(timeout=30):
        proc.kill()
        pytest.fail(f"live never opened the slcan channel: {proc.communicate()}")
    return proc, adapter, slave
