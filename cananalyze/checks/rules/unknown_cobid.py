"""Identifiers outside the CANopen predefined connection set and the network file."""

from __future__ import annotations

import numpy as np

from ...frames import FLAG_EXT
from ...protocol.services import Service
from ..rule import Context, Rule


class UnknownCobIdRule(Rule):
    name = "unknown_cob_id"
    timing = False  # judged by frame order: kept on logs without timestamps
    severity = "warning"
    why = (
        "Traffic no node is configured to send: a misconfigured COB-ID, a foreign device, or a "
        "node-ID clash; find the sender and declare it in the network file if it belongs."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.reported: set[int] = set()

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        rows = ctx.rows(Service.OTHER)
        if rows.size == 0:
            return
        fb = b.frames
        ids = fb.can_id[rows].astype(np.int64) | np.where(fb.flags[rows] & FLAG_EXT, 1 << 32, 0)
        uniq, first = np.unique(ids, return_index=True)
        known = ctx.config.known_cob_ids()
        for cid, i in zip(uniq.tolist(), first.tolist(), strict=True):
            ident = cid & 0x1FFFFFFF
            if cid in self.reported or ident in known:
                continue
            self.reported.add(cid)
            ext = cid >> 32
            text = f"0x{ident:08X} (29-bit)" if ext else f"0x{ident:03X}"
            self.emit(
                fb.t[rows[i]],
                None,
                ident,
                f"frames on unknown identifier {text}",
                text,
                "a configured COB-ID",
                row=rows[i],
            )
