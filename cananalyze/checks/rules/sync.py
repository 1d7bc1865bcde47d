"""SYNC: period against the 0x1006 in force at each SYNC, and counter continuity (columnar)."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.checks.spans import crossing, runs


class SyncRule(Rule):
    name = "sync"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "Synchronous PDOs are sampled and applied on SYNC; a late or irregular SYNC skews every "
        "synchronous control loop; check the SYNC producer's load and 0x1006."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.last_counter = -1
        self.last_t: float | None = None
        self.reported: set[float] = set()  # SYNC times after which tick() saw a silence

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("sync")
        if g.key.size == 0:
            return
        self.subjects.add(None)
        gap = g.gap
        changes = ctx.config.changes(None, 0x1006, 0x1006)
        across = crossing(changes, g.prev, g.t)
        for run, at in runs(changes, g.t) if ctx.timed else ():
            period = ctx.config.sync_period_us(at)
            if not period:
                continue
            p = period / 1e6
            idx = np.arange(run.start, run.stop)[~across[run]]
            bad = idx[np.abs(gap[idx] - p) > self.slack(period / 1000) / 1000]
            if self.reported:
                bad = bad[~np.isin(g.prev[bad], list(self.reported))]
            if bad.size == 0:
                continue
            gaps_ms = [ms(x) for x in gap[bad].tolist()]
            p_ms = period / 1000

            def text(k: np.ndarray, gaps_ms=gaps_ms, p_ms=p_ms) -> list[str]:
                return [f"SYNC period {gaps_ms[j]} ms, 0x1006 is {p_ms:g} ms" for j in k.tolist()]

            self.emit_many(
                g.t[bad],
                None,
                0x080,
                text,
                gaps_ms,
                p_ms,
                row=g.row[bad],
                basis=[ctx.config.origin(None, 0x1006, 0, x, ctx.t0) for x in g.t[bad].tolist()],
            )
        self.last_t = float(g.t[-1])
        fb = ctx.batch.frames
        has = fb.dlc[g.row] >= 1
        if not has.any():
            return
        rows = g.row[has]
        c = fb.data[rows, 0].astype(np.int16)
        prev = np.empty_like(c)
        prev[0] = self.last_counter
        prev[1:] = c[:-1]
        bad = np.flatnonzero((prev >= 0) & (c != prev + 1) & (c != 1))
        if bad.size:  # a counter that jumps on every SYNC: columns, texts when read
            got, after = c[bad], prev[bad]

            def text(k: np.ndarray) -> list[str]:
                return [
                    f"SYNC counter {a} after {b}"
                    for a, b in zip(got[k].tolist(), after[k].tolist(), strict=True)
                ]

            self.emit_many(
                fb.t[rows[bad]],
                None,
                0x080,
                text,
                got,
                after.astype(np.int64) + 1,
                row=rows[bad],
                why="A jump in the SYNC counter means lost SYNC frames or a second SYNC producer; "
                "check 0x1019 and that only one node produces SYNC.",
            )
        self.last_counter = int(c[-1])

    def tick(self, ctx: Context, now: float) -> None:
        """Live: no SYNC for longer than 0x1006 allows, reported once while it lasts."""
        last = self.last_t
        if last is None or last in self.reported:
            return
        period = ctx.config.sync_period_us(last)
        if not period or ctx.config.changes(None, 0x1006, 0x1006).searchsorted(last) != (
            ctx.config.changes(None, 0x1006, 0x1006).searchsorted(now)
        ):
            return
        p_ms = period / 1000
        if (now - last) * 1000 <= p_ms + self.slack(p_ms):
            return
        self.reported.add(last)
        self.emit(
            now,
            None,
            0x080,
            f"no SYNC since {ctx.rel(last)} ({ms(now - last)} ms so far), 0x1006 is {p_ms:g} ms"
            + self.quiet(ctx, last + (p_ms + self.slack(p_ms)) / 1000.0),
            ms(now - last),
            p_ms,
            basis=ctx.config.origin(None, 0x1006, 0, last, ctx.t0),
        )
