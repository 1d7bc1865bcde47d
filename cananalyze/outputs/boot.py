"""`cananalyze boot`: each node's boot story as text or JSON lines (decode/boot)."""

from __future__ import annotations

import json
import sys
from typing import TextIO

from cananalyze.core.records import DecodedBatch
from cananalyze.core.text import printable
from cananalyze.decode.boot import BootFollower, declared_identity, lines
from cananalyze.pipeline.sink import Sink


class BootSink(Sink):
    def __init__(self, out: TextIO = sys.stdout, fmt: str = "text") -> None:
        self.out, self.fmt = out, fmt
        self.follower = BootFollower()
        self.t0: float | None = None

    def write(self, batch: DecodedBatch) -> None:
        if self.t0 is None and len(batch.frames):
            self.t0 = float(batch.frames.t[0])
        self.follower.add(batch)

    def close(self) -> None:
        checker = self.run.checker
        config = checker.config if checker is not None else None
        model = self.run.network
        timed = checker is None or checker.timed is not False
        hb = config.heartbeat_ms if config is not None and timed else None
        stories = self.follower.stories(lambda n: declared_identity(model, n), hb, timed=timed)
        if self.fmt == "jsonl":
            for s in stories:
                self.out.write(json.dumps(s.as_row(), ensure_ascii=False) + "\n")
            return
        if not stories:
            self.out.write("no node's boot in the log\n")
        for k, s in enumerate(stories):
            self.out.write(
                ("\n" if k else "") + "\n".join(map(printable, lines(s, self.t0 or 0.0))) + "\n"
            )
