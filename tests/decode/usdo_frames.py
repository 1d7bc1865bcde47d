"""Decode a few USDO frames written as a candump log: the SDO table, frames, text, JSONL."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path


@dataclass
class Decoded:
    text: str
    jsonl: str

    @property
    def sdo(self) -> list[dict]:
        return [r for r in map(json.loads, self.jsonl.splitlines()) if r["kind"] == "sdo"]

    @property
    def frames(self) -> list[dict]:
        return [r for r in map(json.loads, self.jsonl.splitlines()) if r["kind"] == "frame"]


def candump(frames, fd_rows=None) -> str:
    """(cob_id, bytes) frames 1 ms apart; FD (`##`) unless `fd_rows` leaves them out."""
    lines = []
    for i, (cob, data) in enumerate(frames):
        t = 1.0 + i * 0.001
        if fd_rows is None or i in fd_rows:
            lines.append(f"({t:.6f}) can0 {cob:03X}##0{data.hex().upper()}")
        else:
            lines.append(f"({t:.6f}) can0 {cob:03X}#{data.hex().upper()}")
    return "\n".join(lines) + "\n"


def decode_log(frames, fd_rows=None, fd: bool = False, network: str | None = None) -> Decoded:
    """Decode `frames` (see candump); `fd`: with --fd, `network`: this network file (TOML)."""
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "usdo.log"
        log.write_text(candump(frames, fd_rows))
        extra = ["--fd"] if fd else []
        if network is not None:
            (Path(tmp) / "net.toml").write_text(network)
            extra += ["--network", str(Path(tmp) / "net.toml")]
        out = []
        for fmt in ("text", "jsonl"):
            proc = subprocess.run(
                [sys.executable, "-m", "cananalyze", "decode", str(log), "--format", fmt,
                 "--no-color", *extra],
                capture_output=True, text=True, check=True,
            )  # fmt: skip
            out.append(proc.stdout)
    return Decoded(*out)
