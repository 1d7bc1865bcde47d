"""docs/checks.md's real-trace example of PDO latency after SYNC is what `check --timing`
prints on that trace (line for line, in order; the docs cut lines, never change them)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import ROOT, real_file

DOCS = ROOT / "docs" / "checks.md"
LOG = "isPointless__Sevcon/can_230309_150427.txt"


def _block(after: str) -> list[str]:
    text = DOCS.read_text(encoding="utf-8")
    block = text.split(f"$ {after}\n", 1)[1].split("```", 1)[0]
    return block.splitlines()


def test_the_docs_real_trace_sync_latency_is_the_output(tmp_path: Path):
    log = real_file(LOG)
    network_lines = _block("cat sevcon.toml")
    network_lines = network_lines[
        : network_lines.index(next(x for x in network_lines if x.startswith("$ ")))
    ]
    network = tmp_path / "sevcon.toml"
    network.write_text("\n".join(network_lines) + "\n")
    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(log), "--network", str(network)]
        + ["--timing"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode in (0, 1), run.stderr
    out = run.stdout.splitlines()
    shown = [
        x
        for x in _block("cananalyze check can_230309_150427.txt --network sevcon.toml --timing")
        if x != "..."
    ]
    assert any("after SYNC" in x for x in shown) and len(shown) >= 3
    at = 0
    for line in shown:
        at = out.index(line, at) + 1  # ValueError: the docs show a line check does not print
