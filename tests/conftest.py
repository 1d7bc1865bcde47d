"""Shared test fixtures: where the real data lives, skipping cleanly when it is absent."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
REAL = SHARED / "data" / "real"
SEEDS = SHARED / "seeds"
SAMPLES = ROOT / "samples"


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
