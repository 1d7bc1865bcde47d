"""The same traffic in candump, ASC and BLF decodes to identical records (times relative)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from conftest import ROOT

FORMATS = ["demo.log", "demo.asc", "demo.blf"]


def _jsonl(name: str) -> list[dict]:
    """`decode --format jsonl` of a sample, as the CLI writes it."""
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(ROOT / "samples" / name)]
        + ["--format", "jsonl"],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    return [json.loads(line) for line in out.stdout.splitlines()]


def _records(name: str) -> list[dict]:
    recs = _jsonl(name)
    t0 = recs[0]["t"]
    for r in recs:
        for key in ("t", "t_start", "t_boot"):
            if r.get(key) is not None:
                r[key] = round(r[key] - t0, 6)
        r.pop("channel", None)  # candump names interfaces ("can0"), Vector numbers them ("1")
        if r.get("kind") == "sdo" and r.get("latency_ms") is not None:
            r["latency_ms"] = round(r["latency_ms"], 3)
    return recs


def test_candump_asc_blf_identical():
    base = _records(FORMATS[0])
    assert len(base) > 185  # every frame plus the SDO transaction records
    kinds = {r["kind"] for r in base}
    assert kinds == {"frame", "sdo", "boot"}  # a boot story per node, at the end
    for other in FORMATS[1:]:
        assert _records(other) == base, other


@pytest.mark.parametrize("name", FORMATS)
def test_absolute_time_kept(name):
    first = _jsonl(name)[0]
    assert first["t"] == pytest.approx(1767225600.0, abs=1e-3)  # 2026-01-01T00:00:00Z
