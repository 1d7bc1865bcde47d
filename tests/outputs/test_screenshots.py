"""docs/screenshots.py: docs/checks.md's pictures of the report come out of headless Chromium."""

from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT


@pytest.mark.slow
def test_screenshots_script_draws_the_reports(tmp_path):
    from helpers import browser

    if browser.chromium() is None:
        pytest.skip("no chromium (Debian's package chromium; .ci/run installs it)")
    pytest.importorskip("websockets")
    from PIL import Image

    done = subprocess.run(
        [sys.executable, str(ROOT / "docs" / "screenshots.py"), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr
    # the count of rules grows with the checks; the violations of the faulty sample do not
    assert re.search(r"report-faults\.html: FAIL \d+ rules: 16 violation\(s\)", done.stderr)
    names = {p.name for p in tmp_path.glob("*.png")}
    assert {"report-faults.png", "report-faults-nodes.png"} <= names
    for name in names:
        img = Image.open(tmp_path / name)
        assert img.size == (1280, 900) and (tmp_path / name).stat().st_size < 300_000
        px = np.asarray(img.convert("RGB")).reshape(-1, 3).astype(int)
        coloured = (px.max(axis=1) - px.min(axis=1)) > 60  # plot lines, the verdict, not blank
        assert coloured.sum() > 2000, name
