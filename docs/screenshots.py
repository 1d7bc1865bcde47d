"""The pictures of the HTML report in docs/checks.md: `cananalyze report` of samples/faults.log and
of a real log (PEAK trace pcan3.trc of ../shared/data/real), opened in headless Chromium
(Debian's package) with no network, the first screen saved as PNG in docs/images/.

    python docs/screenshots.py [--out docs/images] [--real DIR]

A page that logs a console error, or whose plots are not drawn, is not saved: the
script stops with the reason. The PNGs are reduced to 256 colours (a plot's flat
colours lose nothing; a third of the size). The browser is the tests' own driver
(`tests/helpers/browser.py`, DevTools over websockets on 127.0.0.1), not a second copy.
"""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from helpers import browser  # noqa: E402

SAMPLES = ROOT / "samples"
REAL = ROOT.parent / "shared" / "data" / "real"
# what the first screen must show: the verdict and at least one drawn plot
QUESTIONS = {
    "verdict": "document.getElementById('verdict-banner').innerText",
    "plots": "document.querySelectorAll('div.plot .main-svg').length",
}


def reports(real: Path) -> list[tuple[str, list[str], str | None]]:
    """(PNG name, `cananalyze report` arguments, section to scroll to) of each picture.
    Paths are given relative to the project, as the page shows them in its title."""
    faults = ["samples/faults.log", "--network", "samples/network.toml"]
    faults += ["--rules", "samples/rules.yaml"]
    out = [("report-faults.png", faults, None), ("report-faults-nodes.png", faults, "nodes")]
    pcan3 = real / "hilch__canopen-message-interpreter" / "pcan3.trc"
    if pcan3.is_file():
        out.append(("report-pcan3.png", [os.path.relpath(pcan3, ROOT)], None))
    else:
        print(f"skipped: {pcan3} (absent)", file=sys.stderr)
    return out


def shoot(args: list[str], page: Path, scroll_to: str | None = None) -> bytes:
    """The report's page rendered: its first screen as PNG, once it drew without errors."""
    cmd = [sys.executable, "-m", "cananalyze", "report", *args, "-o", str(page), "-q"]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if done.returncode not in (0, 1):  # 1: the log has violations (the verdict says so)
        raise SystemExit(f"report failed: {done.stderr.strip()}")
    v = browser.view(page, QUESTIONS, scroll_to=scroll_to)
    if not v.ready or v.errors or not v.answers.get("plots"):
        raise SystemExit(f"{page.name}: not drawn cleanly: ready={v.ready} errors={v.errors}")
    print(f"{page.name}: {v.answers['verdict'].splitlines()[0][:100]}", file=sys.stderr)
    return v.screenshot


def small_png(png: bytes) -> bytes:
    """256 colours, optimised: a third of the size of the browser's PNG."""
    from PIL import Image

    img = Image.open(io.BytesIO(png)).convert("RGB").quantize(colors=256)
    buf = io.BytesIO()
    img.save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images", help="PNG folder")
    ap.add_argument("--real", type=Path, default=REAL, help="the real data (../shared/data/real)")
    a = ap.parse_args(argv)
    if browser.chromium() is None:
        raise SystemExit("no chromium: apt-get install chromium (Debian's package)")
    a.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name, args, section in reports(a.real):
            page = Path(tmp) / name.replace(".png", ".html")
            png = small_png(shoot(args, page, section))
            (a.out / name).write_bytes(png)
            print(f"{a.out / name}: {len(png) / 1e3:.0f} kB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
