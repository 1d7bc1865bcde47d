"""`decode --signals`: one `signal` record per decoded PDO value, straight from the SignalBlocks.

Values leave numpy in bulk (`tolist()` per column) rather than row by row through
`DecodedBatch.fields`, so printing millions of values stays cheap.
"""

from __future__ import annotations

import json
import math
from typing import TextIO

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.pipeline.sink import Sink


def signal_records(batch: DecodedBatch, mask: np.ndarray | None = None) -> list[dict]:
    """`{kind: signal, t, node, pdo, cob_id, signal, value, unit}` in frame order."""
    t = batch.frames.t
    out: list[tuple[int, int, dict]] = []
    for sb in batch.signals:
        rows = sb.rows if mask is None else sb.rows[mask[sb.rows]]
        keep = None if mask is None else mask[sb.rows]
        times = t[rows].tolist()
        row_list = rows.tolist()
        for k, (name, col) in enumerate(sb.columns.items()):
            values = (col if keep is None else col[keep]).tolist()
            unit = sb.units.get(name)
            for r, ts, v in zip(row_list, times, values, strict=True):
                if isinstance(v, float) and not math.isfinite(v):
                    v = None
                out.append(
                    (
                        r,
                        k,
                        {
                            "kind": "signal",
                            "t": ts,
                            "node": sb.node,
                            "pdo": sb.pdo,
                            "cob_id": sb.cob_id,
                            "signal": name,
                            "value": v,
                            "unit": unit,
                        },
                    )
                )
    out.sort(key=lambda x: (x[0], x[1]))
    return [rec for _, _, rec in out]


class SignalWriter(Sink):
    """`--signals`: JSON lines with Unix times, or text lines timed like the frame lines
    (seconds from the log's first frame, or as logged with `--time abs`)."""

    def __init__(self, out: TextIO, fmt: str = "jsonl") -> None:
        self.out = out
        self.fmt = fmt
        self.t0: float | None = None

    def write(self, batch: DecodedBatch, mask: np.ndarray | None = None) -> None:
        recs = signal_records(batch, mask)
        if not recs:
            return
        if self.fmt == "jsonl":
            lines = [json.dumps(r, separators=(",", ":"), ensure_ascii=False) for r in recs]
        else:
            if self.t0 is None:
                run = getattr(self, "run", None)
                if run is not None and run.options.time == "abs":
                    self.t0 = 0.0
                elif run is not None and run.t0 is not None:
                    self.t0 = run.t0
                else:
                    self.t0 = recs[0]["t"]
            lines = []
            for r in recs:
                v = r["value"]
                shown = f"{v:.6g}" if isinstance(v, float) else v
                unit = f" {r['unit']}" if r["unit"] else ""
                who = f"node {r['node']} " if r["node"] >= 0 else ""  # a DBC message: no node
                lines.append(
                    f"{r['t'] - self.t0:12.6f}  {who}{r['pdo']} 0x{r['cob_id']:03X} "
                    f"{r['signal']}={shown}{unit}"
                )
        self.out.write("\n".join(lines) + "\n")
