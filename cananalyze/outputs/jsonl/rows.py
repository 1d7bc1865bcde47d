"""`--format jsonl`: one JSON object per line; field names are a stable API (docs/outputs.md)."""

from __future__ import annotations

import contextlib
from typing import TextIO

import numpy as np

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RECONSTRUCTED, FLAG_RTR
from cananalyze.core.records import DecodedBatch
from cananalyze.outputs.background import ByteSink
from cananalyze.outputs.fields import row_fields
from cananalyze.outputs.jsonl.encode import clean_fields, dumps
from cananalyze.outputs.jsonl.records import jsonl_records
from cananalyze.pipeline.sink import Sink
from cananalyze.protocol.services import SERVICE_NAMES


def frame_record(batch: DecodedBatch, i: int) -> dict:
    fb = batch.frames
    fl = int(fb.flags[i])
    rec: dict = {
        "kind": "frame",
        "t": float(fb.t[i]),
        "channel": fb.channel_name(i),
        "can_id": int(fb.can_id[i]),
        "dlc": int(fb.dlc[i]),
        "data": fb.payload(i).hex() if not fl & FLAG_RTR else "",
    }
    if fl & FLAG_RTR:
        rec["rtr"] = True
    if fl & FLAG_EXT:
        rec["ext"] = True
    if fl & FLAG_ERR:
        rec["error"] = True
    if fl & FLAG_FD:
        rec["fd"] = True
    if fl & FLAG_RECONSTRUCTED:
        rec["reconstructed"] = True
    rec["service"] = SERVICE_NAMES[int(batch.service[i])]
    node = int(batch.node[i])
    rec["node"] = None if node < 0 else node
    if batch.pdo[i]:
        rec["pdo"] = int(batch.pdo[i])
    rec.update(clean_fields(row_fields(batch, i)))
    return rec


class JsonlWriter(Sink):
    """JSON lines of decoded batches: as columns where it can (`jsonl_columns`), else
    row by row; with `background`, finished and written by a worker thread
    (`background.ByteSink`), whose error `close()` raises."""

    def __init__(self, out: TextIO, frames: bool = True, background: bool = False) -> None:
        self.out = out
        self.frames = frames
        self._sink = ByteSink(out, background, "jsonl-writer")

    def write(self, batch: DecodedBatch, mask: np.ndarray | None = None) -> None:
        if self.frames:
            from cananalyze.outputs.jsonl.columns import render  # imports this module

            rendered = render(batch, mask)
            if rendered is not None:
                self._sink.put(rendered)
                return
        by_row: dict[int, list[dict]] = {}
        records = jsonl_records(batch)
        for row, rec in records:
            by_row.setdefault(row, []).append(rec)
        rows = range(len(batch)) if mask is None else np.flatnonzero(mask).tolist()
        lines = []
        shown = set()
        if self.frames:
            for i in rows:
                lines.append(dumps(frame_record(batch, i)))
                shown.add(i)
                for rec in by_row.get(i, ()):
                    lines.append(dumps(rec))
        for row, rec in records:
            if row not in shown:
                lines.append(dumps(rec))
        if lines:
            self._sink.put(("\n".join(lines) + "\n").encode("utf-8"))

    def close(self) -> None:
        """Wait for the worker, if any; re-raise its error here."""
        self._sink.close()

    def abort(self) -> None:
        with contextlib.suppress(Exception):
            self._sink.close()
