"""The optional C helper: a failed build says so in one line and still succeeds, and
`cananalyze --version` tells which path an installed copy takes."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from conftest import ROOT

from cananalyze import __version__

NOT_BUILT = "cananalyze: C helper not built (no compiler?): using the pure-Python path"


def test_build_without_a_compiler_says_so_and_succeeds(tmp_path: Path) -> None:
    env = dict(os.environ, CC="/bin/false")  # every compile fails, as without gcc
    out = subprocess.run(
        [sys.executable, "setup.py", "-q", "build_ext"]
        + ["--build-lib", str(tmp_path / "lib"), "--build-temp", str(tmp_path / "tmp")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr
    said = [line for line in out.stderr.splitlines() if line.startswith(NOT_BUILT)]
    assert len(said) == 1, out.stderr
    assert not list(tmp_path.rglob("_speedups*.so"))


def _version(**env: str) -> str:
    out = subprocess.run(
        [sys.executable, *env.pop("args", ["-m", "cananalyze"]), "--version"],
        cwd=ROOT,
        env=dict(os.environ, **env),
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.strip()


def test_version_says_whether_the_helper_is_in_use() -> None:
    head = f"cananalyze {__version__}"
    assert _version(CANANALYZE_PURE="1") == f"{head} (pure-Python path: CANANALYZE_PURE is set)"
    # an install where the extension did not build: importing it fails
    missing = (
        "import sys; sys.modules['cananalyze.runtime._speedups'] = None; "
        "from cananalyze.cli.main import main; sys.argv[0] = 'cananalyze'; main()"
    )
    assert _version(CANANALYZE_PURE="", args=["-c", missing]) == (
        f"{head} (pure-Python path: compiled helper not built)"
    )
    built = list((ROOT / "cananalyze" / "runtime").glob("_speedups*.so"))
    if built:
        assert _version(CANANALYZE_PURE="") == f"{head} (compiled helper in use)"
