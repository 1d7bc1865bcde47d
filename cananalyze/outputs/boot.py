"""`cananalyze boot`: each node's boot story as text or JSON lines (decode/boot), as the
decoder's commissioning processor judged it at the end of the log (the one follower)."""

from __future__ import annotations

import json
import sys
from typing import TextIO

from cananalyze.core.records import DecodedBatch
from cananalyze.core.text import printable
from cananalyze.decode.boot import lines
from cananalyze.decode.commissioning import Commissioning
from cananalyze.pipeline.sink import Sink


class BootSink(Sink):
    def __init__(self, out: TextIO = sys.stdout, fmt: str = "text") -> None:
        self.out, self.fmt = out, fmt
        self.t0: float | None = None

    def write(self, batch: DecodedBatch) -> None:
        if self.t0 is None and len(batch.frames):
            self.t0 = float(batch.frames.t[0])

    def close(self) -> None:
        producers = self.run.decoder.processors_of(Commissioning)
        several = len(producers) > 1  # a log of several buses: each bus's nodes
        stories = [(bus, s) for bus, c in producers for s in c.stories]
        if self.fmt == "jsonl":
            for bus, s in stories:
                row = s.as_row() | ({"bus": bus} if several else {})
                self.out.write(json.dumps(row, ensure_ascii=False) + "\n")
            return
        if not stories:
            self.out.write("no node's boot in the log\n")
        for k, (bus, s) in enumerate(stories):
            text = lines(s, self.t0 or 0.0)
            if several:
                text[0] = f"{bus} {text[0]}"
            self.out.write(("\n" if k else "") + "\n".join(map(printable, text)) + "\n")
