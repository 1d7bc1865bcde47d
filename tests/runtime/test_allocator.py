"""The command line's allocator settings: applied for batch commands, never overriding the user."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from cananalyze.runtime import allocator

ROOT = Path(__file__).resolve().parents[2]

PROBE = """
import os, sys
from cananalyze.runtime import allocator
ok = allocator.tune()
import pyarrow as pa
print(ok, os.environ.get("ARROW_DEFAULT_MEMORY_POOL", "-"), pa.default_memory_pool().backend_name)
"""


def _probe(env: dict) -> list[str]:
    out = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    )
    return out.stdout.split()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="mallopt is glibc's")
def test_tune_sets_glibc_and_arrow_jemalloc_pool():
    env = {k: v for k, v in os.environ.items() if k != "ARROW_DEFAULT_MEMORY_POOL"}
    ok, pool, backend = _probe(env)
    assert ok == "True"
    import pyarrow as pa

    if "jemalloc" in pa.supported_memory_backends():
        assert allocator.arrow_has_jemalloc()
        assert pool == "jemalloc" and backend == "jemalloc"
    else:  # a pyarrow built without it: Arrow's own choice, and no warning
        assert not allocator.arrow_has_jemalloc()
        assert pool == "-"


def test_no_pool_warning_on_stderr():
    """Arrow prints a warning for a pool it lacks; tune() must never name one."""
    env = {k: v for k, v in os.environ.items() if k != "ARROW_DEFAULT_MEMORY_POOL"}
    out = subprocess.run(
        [sys.executable, "-c", PROBE], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    )
    assert "Unsupported backend" not in out.stderr


def test_tune_keeps_the_users_arrow_pool():
    env = dict(os.environ, ARROW_DEFAULT_MEMORY_POOL="mimalloc")
    _, pool, backend = _probe(env)
    assert pool == "mimalloc"
    assert backend == "mimalloc"


def test_cli_tunes_only_batch_commands(monkeypatch):
    from cananalyze.cli import main

    calls = []
    monkeypatch.setattr(allocator, "tune", lambda: calls.append(1) or True)
    assert main.main(["devices"]) == 0
    assert calls == []
    sample = ROOT / "samples" / "demo.log"
    assert main.main(["decode", str(sample), "--summary"]) == 0
    assert calls == [1]


@pytest.mark.parametrize(
    ("config", "expected"),
    [
        ("#define ARROW_JEMALLOC\n#define ARROW_MIMALLOC\n", True),
        ("#define ARROW_MIMALLOC\n/* #undef ARROW_JEMALLOC */\n", False),
        (None, False),  # no headers shipped
    ],
)
def test_arrow_has_jemalloc_reads_the_build_config(tmp_path, monkeypatch, config, expected):
    import importlib.machinery
    import importlib.util

    pkg = tmp_path / "pyarrow"
    (pkg / "include" / "arrow" / "util").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    if config is not None:
        (pkg / "include" / "arrow" / "util" / "config.h").write_text(config)
    spec = importlib.machinery.ModuleSpec("pyarrow", None, origin=str(pkg / "__init__.py"))
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: spec)
    assert allocator.arrow_has_jemalloc() is expected
