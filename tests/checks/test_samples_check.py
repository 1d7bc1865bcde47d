"""`cananalyze check` on the scenario samples finds exactly what samples/README.md lists."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from conftest import SAMPLES

START = 1767225600.0  # the samples' simulated clock starts at 2026-01-01T00:00:00Z

# (seconds after start, rule, node) for each fault in the README's table
FAULTS = sorted(
    [
        (1.5, "emcy", 3),
        (2.0, "emcy", 3),
        (2.6, "emcy", 3),  # MCB-560 EMCYs
        (2.5, "error_frames", None),  # 3 CAN error frames
        (3.2, "emcy", 7),
        (3.2, "emcy", 7),  # I-7231D EMCY, and never reset
        (3.88, "assert_signal", 5),
        (4.38, "assert_signal", 5),
        (4.88, "assert_signal", 5),  # ch3 out of range
        (4.41, "heartbeat", 6),
        (6.01, "assert_heartbeat", 6),  # DAT 7130 heartbeat dropout
        (6.52, "pdo_async", 3),  # inhibit time violation
        (7.0, "sdo", 3),
        (7.0, "sdo", 5),  # two aborts
        (7.82, "pdo_async", 3),  # event timer stall
        (8.5, "sdo", 5),  # SDO timeout (aborted by the master)
    ]
)


def _check(name: str, tmp_path) -> tuple[int, list[tuple[float, str, int | None]]]:
    out = tmp_path / "findings.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "cananalyze",
            "check",
            str(SAMPLES / name),
            "--rules",
            str(SAMPLES / "rules.yaml"),
            "--network",
            str(SAMPLES / "network.toml"),
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
    )
    found = [(round(r["t"] - START, 2), r["rule"], r["node"]) for r in json.loads(out.read_text())]
    return proc.returncode, sorted(found, key=lambda x: (x[0], x[1], x[2] or 0))


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_faults_sample_gives_exactly_the_listed_findings(suffix, tmp_path):
    rc, found = _check("faults" + suffix, tmp_path)
    assert rc == 1
    assert found == sorted(FAULTS, key=lambda x: (x[0], x[1], x[2] or 0))


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_commissioning_sample_is_clean(suffix, tmp_path):
    rc, found = _check("commissioning" + suffix, tmp_path)
    assert (rc, found) == (0, [])
