"""SdoProcessor: runs the SDO tracker over the SDO rows of each batch.

SDO traffic is rare and stateful, so this is one of the places where per-frame
Python is right. Rows on the default channels are found by the classifier;
extra channels learnt from 0x1200-0x12FF writes are found by the tracker.
"""

from __future__ import annotations

import numpy as np

from ..decoded import DecodedBatch
from ..frames import FLAG_ERR, FLAG_EXT, FLAG_RTR
from ..protocol.services import Service
from .tracker import SdoTracker


class SdoProcessor:
    def __init__(self, tracker: SdoTracker | None = None) -> None:
        self.tracker = tracker or SdoTracker()
        self._offset = 0  # frames before the current batch, so refs are global

    def _rows(self, batch: DecodedBatch) -> np.ndarray:
        svc = batch.service
        is_sdo = (svc == Service.SDO_REQUEST) | (svc == Service.SDO_RESPONSE)
        extra = self.tracker.extra_cob_ids()
        if extra:
            plain = (batch.frames.flags & (FLAG_EXT | FLAG_ERR | FLAG_RTR)) == 0
            on_extra = np.isin(batch.frames.can_id, np.fromiter(extra, np.uint32)) & plain
            for row in np.flatnonzero(on_extra & ~is_sdo):
                node, is_request = self.tracker.channel_of(int(batch.frames.can_id[row]))
                batch.service[row] = Service.SDO_REQUEST if is_request else Service.SDO_RESPONSE
                batch.node[row] = node
                batch.pdo[row] = 0
            is_sdo |= on_extra
        return np.flatnonzero(is_sdo & ((batch.frames.flags & FLAG_RTR) == 0))

    def process(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        n = len(fb)
        for row in self._rows(batch).tolist():
            role = self.tracker.feed(float(fb.t[row]), int(fb.can_id[row]), fb.payload(row), self._offset + row)
            # the tracker knows block segments, which carry no command specifier: its view wins
            note = {"role": role.text, "command": role.command, "index": role.index, "subindex": role.subindex}
            if role.problem:
                note["sdo_problem"] = role.problem
            batch.notes.setdefault(row, {}).update(note)
            self._emit(batch)
        if n:
            self.tracker.advance(float(fb.t[-1]))
            self._emit(batch)
        self._offset += n

    def finish(self, batch: DecodedBatch) -> None:
        self.tracker.finish()
        self._emit(batch)

    def _emit(self, batch: DecodedBatch) -> None:
        n = len(batch)
        for tx in self.tracker.pop_completed():
            ref = tx.ref if tx.ref is not None else -1
            row = ref - self._offset
            if not 0 <= row < n:
                row = n - 1  # completed by time passing (timeout) or at the end: after this batch
            batch.add_record(row, tx.to_record())
