"""A minimal SDO Processor for tests: runs the SdoTracker over SDO rows, records at their row.

Stands in for the pipeline's SDO processor so the network model can be tested on
logs whose configuration is written by SDO inside the log.
"""

from __future__ import annotations

import numpy as np

from cananalyze.decoded import DecodedBatch
from cananalyze.protocol.services import Service
from cananalyze.sdo import SdoTracker


class SdoFeed:
    def __init__(self) -> None:
        self.tracker = SdoTracker()

    def process(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        rows = np.flatnonzero(
            (batch.service == Service.SDO_REQUEST) | (batch.service == Service.SDO_RESPONSE)
        )
        for i in rows.tolist():
            self.tracker.feed(float(fb.t[i]), int(fb.can_id[i]), fb.payload(i), i)
            for tx in self.tracker.pop_completed():
                batch.add_record(tx.ref if tx.ref is not None else i, tx.to_record())

    def finish(self, batch: DecodedBatch) -> None:
        self.tracker.finish()
        for tx in self.tracker.pop_completed():
            batch.add_record(0, tx.to_record())
