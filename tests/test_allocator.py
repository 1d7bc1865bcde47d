"""The command line's allocator settings: applied for batch commands, never overriding the user."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PROBE = """
import os, sys
from cananalyze import allocator
ok = allocator.tune()
import pyarrow as pa
print(ok, os.environ["ARROW_DEFAULT_MEMORY_POOL"], pa.default_memory_pool().backend_name)
"""


def _probe(env: dict) -> list[str]:
    out = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.split()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="mallopt is glibc's")
def test_tune_sets_glibc_and_arrow_system_pool():
    env = {k: v for k, v in os.environ.items() if k != "ARROW_DEFAULT_MEMORY_POOL"}
    ok, pool, backend = _probe(env)
    assert ok == "True"
    assert pool == "system" and backend == "system"


def test_tune_keeps_the_users_arrow_pool():
    env = dict(os.environ, ARROW_DEFAULT_MEMORY_POOL="mimalloc")
    _, pool, backend = _probe(env)
    assert pool == "mimalloc"
    assert backend == "mimalloc"


def test_cli_tunes_only_batch_commands(monkeypatch):
    from cananalyze import allocator
    from cananalyze.cli import main

    calls = []
    monkeypatch.setattr(allocator, "tune", lambda: calls.append(1) or True)
    assert main.main(["devices"]) == 0
    assert calls == []
    sample = ROOT / "samples" / "demo.log"
    assert main.main(["decode", str(sample), "--summary"]) == 0
    assert calls == [1]
