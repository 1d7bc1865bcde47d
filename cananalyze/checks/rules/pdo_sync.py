"""Synchronous TPDOs: type n every n-th SYNC, inside the window 0x1007; type 0 only after a SYNC.

Each PDO is judged by its parameters and the window in force at its time.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.checks.spans import pdo_stretches, runs, sync_before
from cananalyze.protocol.services import Service


class PdoSyncRule(Rule):
    name = "pdo_sync"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "A synchronous PDO outside its SYNC slot carries data sampled at the wrong time or arrives "
        "after the consumers applied their inputs; check the transmission type (0x18xx:2) and the "
        "node's processing time against 0x1007."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.sync_count = 0
        self.last_sync_t = np.nan
        self.last_sync_no: dict[int, int] = {}

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        srows = ctx.rows(Service.SYNC)
        st = b.frames.t[srows]
        g = ctx.gaps("pdo")
        if g.key.size:
            windows = ctx.config.changes(None, 0x1007, 0x1007)
            for cob, (node, pdo), idx, judged in pdo_stretches(ctx, g):
                if pdo.direction != "tx" or pdo.transmission_type > 240:
                    continue
                n = pdo.transmission_type
                self.subjects.add(node)
                rows = g.row[idx]
                k, last_t = sync_before(srows, st, rows, self.last_sync_t)
                no = self.sync_count + k
                prev = np.empty_like(no)
                prev[1:] = no[:-1]
                prev[0] = self.last_sync_no.get(cob, -1)
                prev[~judged] = -1  # the PDO's parameters changed since the previous one
                self.last_sync_no[cob] = int(no[-1])
                t = g.t[idx]
                if n == 0:
                    bad = np.flatnonzero((prev >= 0) & (no == prev))
                    text = "acyclic synchronous PDO (type 0) sent twice without a SYNC between"
                else:
                    bad = np.flatnonzero((prev >= 0) & (no - prev != n))
                    text = f"sent {{}} SYNCs after the previous one, transmission type {n}"
                if bad.size:  # per frame: as columns
                    after = (no[bad] - prev[bad]).astype(np.int64)
                    self.emit_many(
                        t[bad],
                        node,
                        cob,
                        lambda k, after=after, text=text: [
                            text.format(a) for a in after[k].tolist()
                        ],
                        after,
                        max(n, 1),
                        row=rows[bad],
                    )
                for run, at in runs(windows, t) if ctx.timed else ():
                    window = ctx.config.sync_window_us(at)
                    if not window:
                        continue
                    late = t[run] - last_t[run]
                    bad = np.flatnonzero(late > window / 1e6) + run.start
                    for i in self.capped(bad, t[bad], node, cob).tolist():
                        self.emit(
                            t[i],
                            node,
                            cob,
                            f"sent {ms(t[i] - last_t[i])} ms after SYNC, window 0x1007 is "
                            f"{window / 1000:g} ms",
                            ms(t[i] - last_t[i]),
                            window / 1000,
                            row=rows[i],
                            basis=ctx.config.origin(None, 0x1007, 0, float(t[i]), ctx.t0),
                        )
        self.sync_count += srows.size
        if srows.size:
            self.last_sync_t = float(st[-1])
