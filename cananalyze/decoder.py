"""Decoder: one object that turns FrameBatches into DecodedBatches, offline or live.

Classification is columnar (protocol.cobid); stateful work is done by a chain of
processors, each seeing the whole DecodedBatch in order: the SDO tracker, the
network model that follows configuration writes, the PDO decoder, the checks.
Live sniffing feeds small batches to the same object, so both give the same records.
"""

from __future__ import annotations

from typing import Protocol

from .frames import FrameBatch
from .protocol.cobid import CobClassifier
from .records import DecodedBatch


class Processor(Protocol):
    def process(self, batch: DecodedBatch) -> None:
        """Add notes, records or signals to the batch; keep state for the next one."""

    def finish(self, batch: DecodedBatch) -> None:
        """End of log: emit what is still pending into `batch` (an empty batch)."""


class Decoder:
    def __init__(self, processors: list[Processor] | None = None) -> None:
        self.classifier = CobClassifier()
        self.processors: list[Processor] = list(processors or [])

    def decode(self, batch: FrameBatch) -> DecodedBatch:
        c = self.classifier.classify(batch)
        out = DecodedBatch(batch, c.service, c.node, c.pdo)
        for p in self.processors:
            p.process(out)
        return out

    def finish(self) -> DecodedBatch:
        """A zero-row batch carrying the records that only the end of the log completes."""
        empty = self.decode(FrameBatch.empty())
        for p in self.processors:
            p.finish(empty)
        return empty
