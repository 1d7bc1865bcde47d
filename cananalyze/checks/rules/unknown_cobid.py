"""Identifiers outside the CANopen predefined connection set and the network file."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.core.frames import FLAG_EXT
from cananalyze.protocol.services import Service

# Unknown identifiers listed one by one (per bus); frames on more are counted in one
# finding at the end. A log of random 29-bit identifiers made a finding per frame: 200k
# frames took 5 s and 390 MB in `check`, growing with the log.
MAX_LISTED = 1000


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
        self.reported: set[int] = set()  # at most MAX_LISTED
        self.unlisted_frames = 0  # frames on unknown identifiers past MAX_LISTED
        self.unlisted_t: float | None = None  # the first of them

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        rows = ctx.rows(Service.OTHER)
        if rows.size == 0:
            return
        fb = b.frames
        ids = fb.can_id[rows].astype(np.int64) | np.where(fb.flags[rows] & FLAG_EXT, 1 << 32, 0)
        uniq, first, counts = np.unique(ids, return_index=True, return_counts=True)
        known = ctx.config.known_cob_ids()
        fresh = ~np.isin(uniq & 0x1FFFFFFF, np.fromiter(known, np.int64, len(known)))
        if self.reported:
            fresh &= ~np.isin(uniq, np.fromiter(self.reported, np.int64, len(self.reported)))
        at = np.flatnonzero(fresh)
        at = at[np.argsort(first[at], kind="stable")]  # the first seen are listed
        room = MAX_LISTED - len(self.reported)
        listed, unlisted = at[:room], at[room:]
        if unlisted.size:
            self.unlisted_frames += int(counts[unlisted].sum())
            t = float(fb.t[rows[first[unlisted]]].min())
            self.unlisted_t = t if self.unlisted_t is None else min(self.unlisted_t, t)
        for cid, i in zip(uniq[listed].tolist(), first[listed].tolist(), strict=True):
            self.reported.add(cid)
            ident = cid & 0x1FFFFFFF
            text = f"0x{ident:08X} (29-bit)" if cid >> 32 else f"0x{ident:03X}"
            self.emit(
                fb.t[rows[i]],
                None,
                ident,
                f"frames on unknown identifier {text}",
                text,
                "a configured COB-ID",
                row=rows[i],
            )

    def finish(self, ctx: Context) -> None:
        if self.unlisted_frames:
            self.emit(
                self.unlisted_t,
                None,
                None,
                f"{self.unlisted_frames} more frames on unknown identifiers, not listed one by "
                f"one (the first {MAX_LISTED} identifiers are)",
                self.unlisted_frames,
                0,
            )
