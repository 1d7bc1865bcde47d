"""Data frames on error-control COB-IDs that are not 1 byte: one finding per COB-ID.

CiA 301's heartbeat, boot-up and guard response are exactly 1 byte, so the classifier
calls any other length `errctl_invalid` and no node's state follows it. Such frames
are another protocol on these identifiers (a car bus's 0x708) or a broken stack; one
finding per COB-ID at the end, not one per frame, says which and how many.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.protocol.nmt import ERRCTL_BYTES
from cananalyze.protocol.services import Service


class ErrctlLengthRule(Rule):
    name = "errctl_length"
    severity = "warning"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "Heartbeat, boot-up and node-guarding frames are 1 byte (CiA 301), so these frames "
        "report no NMT state and were not read as one: another protocol uses these "
        "identifiers, or a stack sends a wrong length; find the sender."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.count = np.zeros(2048, np.int64)  # per COB-ID
        self.first = np.full(2048, np.nan)
        self.node = np.full(2048, -1, np.int64)
        self.shortest = np.full(2048, 255, np.int64)
        self.longest = np.zeros(2048, np.int64)

    def process(self, ctx: Context) -> None:
        rows = ctx.rows(Service.ERRCTL_INVALID)
        if rows.size == 0:
            return
        fb = ctx.batch.frames
        ids = fb.can_id[rows].astype(np.intp)  # the classifier marks 11-bit frames only
        dlc = fb.dlc[rows].astype(np.int64)
        np.add.at(self.count, ids, 1)
        np.minimum.at(self.shortest, ids, dlc)
        np.maximum.at(self.longest, ids, dlc)
        cob, at = np.unique(ids, return_index=True)  # rows ascend: each COB-ID's first
        new = np.isnan(self.first[cob])
        self.first[cob[new]] = fb.t[rows[at[new]]]
        self.node[cob[new]] = ctx.batch.node[rows[at[new]]]

    def finish(self, ctx: Context) -> None:
        for cob in np.flatnonzero(self.count).tolist():
            n, lo, hi = int(self.count[cob]), int(self.shortest[cob]), int(self.longest[cob])
            node = int(self.node[cob])
            node = None if node < 0 else node
            self.subjects.add(node)
            size = lo if lo == hi else f"{lo}-{hi}"  # measured: the data bytes
            self.emit(
                float(self.first[cob]),
                node,
                cob,
                f"{n} frame{'s' if n != 1 else ''} on 0x{cob:03X} with {size} data bytes; "
                f"error control (heartbeat/boot-up/guarding) is {ERRCTL_BYTES} byte",
                size,
                ERRCTL_BYTES,
            )
