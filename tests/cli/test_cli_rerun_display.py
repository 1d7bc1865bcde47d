"""`--rerun` on a Linux machine without a display: one line, exit 2, before any viewer is
spawned or any frame read (it used to end in a gRPC traceback after 17 s, exit 1)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from conftest import ROOT, SAMPLES

from cananalyze.cli.common import require_display_for_viewer
from cananalyze.core.errors import UsageError

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a Linux check")


def _headless(*args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["PYTHONPATH"] = str(ROOT)
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
    )


@linux_only
def test_decode_rerun_without_display_fails_in_one_line():
    done = _headless("decode", str(SAMPLES / "demo.log"), "--rerun")
    assert done.returncode == 2
    assert done.stdout == ""  # nothing decoded: it failed before reading
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert "no display" in done.stderr and "$DISPLAY" in done.stderr
    assert "--connect HOST:PORT" in done.stderr and "export LOG --rrd FILE" in done.stderr


@linux_only
def test_live_rerun_without_display_fails_in_one_line():
    done = _headless("live", "-i", "virtual", "-c", "headless", "--rerun", "--duration", "5")
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr
    assert "no display" in done.stderr and "--rrd FILE" in done.stderr


@linux_only
@pytest.mark.parametrize(
    "env, fails",
    [
        ({}, True),
        ({"DISPLAY": ""}, True),
        ({"DISPLAY": ":0"}, False),
        ({"WAYLAND_DISPLAY": "wayland-0"}, False),
    ],
)
def test_which_environments_have_a_display(env, fails):
    if fails:
        with pytest.raises(UsageError, match="--rrd FILE"):
            require_display_for_viewer("use --rrd FILE", environ=env)
    else:
        require_display_for_viewer("use --rrd FILE", environ=env)
