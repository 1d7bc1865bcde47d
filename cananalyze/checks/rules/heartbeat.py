"""Heartbeat rules: dropouts against 0x1017, heartbeats that stop, consumer time expiry.

Each heartbeat is judged by the 0x1017 in force at its time; a new value or a reset
restarts the producer's timer, so a gap across one is judged from there. 0x1017 = 0
means no heartbeat is expected. Without a known producer time the expected period is
inferred from the node's median gap, and findings say so.
"""

from __future__ import annotations

import numpy as np

from ..rule import Context, Rule, ms
from ..spans import crossing, runs


class HeartbeatRule(Rule):
    name = "heartbeat"
    needs_gaps = ("heartbeat",)  # finish() infers periods from every gap (Timing.all_gaps)
    why = (
        "A node whose heartbeat is late looks dead to its consumers, which then stop or fault; "
        "check the node's load, its 0x1017 setting and the bus load at that moment."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.last_seen: dict[int, float] = {}
        # node -> start times of the gaps judged without a known period (no 0x1017 known
        # at that time): finish() infers the period for these from the median gap
        self.unjudged: dict[int, list[np.ndarray]] = {}

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("heartbeat")
        if g.key.size == 0:
            return
        gap = g.gap
        for node, sl in g.groups():
            self.subjects.add(node)
            t, prev = g.t[sl], g.prev[sl]
            self.last_seen[node] = float(t[-1])
            deadline, period = self._deadlines(ctx, node, prev, t)
            unknown = np.isnan(deadline) & ~np.isnan(prev)
            if unknown.any():
                self.unjudged.setdefault(node, []).append(prev[unknown])
            bad = np.flatnonzero(t > deadline) + sl.start
            for i in self.capped(bad, g.prev[bad], node, 0x700 + node).tolist():
                self.emit(
                    g.prev[i],
                    node,
                    0x700 + node,
                    f"heartbeat dropout: no heartbeat for {ms(gap[i])} ms from {ctx.rel(g.prev[i])}",
                    ms(gap[i]),
                    float(period[i - sl.start]),
                    row=g.row[i],
                )
        self._consumers(ctx, g)

    def _due(self, start: float, period: float | None) -> float:
        """When the next heartbeat is late, from `start` (NaN: unknown, inf: 0x1017 is 0)."""
        if period is None:
            return np.nan
        return np.inf if period == 0 else start + period * (1 + self.tolerance) / 1000.0

    def _deadlines(self, ctx: Context, node: int, prev, t) -> tuple[np.ndarray, np.ndarray]:
        """Per heartbeat, when it was late at the latest, and the period in force (ms)."""
        changes = ctx.config.changes(node, 0x1017, 0x1017)
        deadline = np.full(t.size, np.nan)
        period = np.full(t.size, np.nan)
        across = crossing(changes, prev, t)
        for sl, at in runs(changes, t):
            p = ctx.config.heartbeat_ms(node, at)
            if p is None:
                continue
            inside = ~across[sl]
            period[sl][inside] = p
            deadline[sl][inside] = (
                np.inf if p == 0 else prev[sl][inside] + p * (1 + self.tolerance) / 1000.0
            )
        for i in np.flatnonzero(across & ~np.isnan(prev)).tolist():
            start = float(prev[i])
            due, p, _ = self._deadline(ctx, node, start, changes, float(t[i]))
            if t[i] <= due and ctx.config.heartbeat_ms(node, start) is None:
                due = np.nan  # began with 0x1017 unknown: the median judges it (finish)
            deadline[i], period[i] = due, np.nan if p is None else p
        return deadline, period

    def _deadline(self, ctx: Context, node: int, start: float, changes, until: float):
        """(deadline, period, start of its stretch) after a heartbeat at `start`, following
        the changes up to `until`: a new 0x1017 or a reset restarts the producer's timer."""
        p = ctx.config.heartbeat_ms(node, start)
        due = self._due(start, p)
        for c in changes[(changes > start) & (changes <= until)].tolist():
            if c > due:  # late before the change (NaN: not known, so go on)
                break
            start, p = c, ctx.config.heartbeat_ms(node, c)
            due = self._due(c, p)
        return due, p, start

    def _consumers(self, ctx: Context, g) -> None:
        """0x1016 consumer time expiry, judged by the entries in force at each heartbeat."""
        changes = ctx.config.changes(None, 0x1016, 0x1016)
        gap = g.gap
        for sl_run, at in runs(changes, g.t):
            consumers: dict[int, list[tuple[int, float]]] = {}
            for consumer in range(1, 128):
                for producer, limit in ctx.config.heartbeat_consumers(consumer, at).items():
                    consumers.setdefault(producer, []).append((consumer, limit))
            if not consumers:
                continue
            across = crossing(changes, g.prev[sl_run], g.t[sl_run])
            for node, sl in g.groups():
                lo, hi = max(sl.start, sl_run.start), min(sl.stop, sl_run.stop)
                for consumer, limit_ms in consumers.get(node, ()) if lo < hi else ():
                    late = (gap[lo:hi] > limit_ms / 1000.0) & ~across[
                        lo - sl_run.start : hi - sl_run.start
                    ]
                    for i in (np.flatnonzero(late) + lo).tolist():
                        self.emit(
                            g.prev[i] + limit_ms / 1000.0,
                            node,
                            0x700 + node,
                            f"node {consumer}'s heartbeat consumer time for node {node} expired "
                            f"(gap {ms(gap[i])} ms)",
                            ms(gap[i]),
                            limit_ms,
                            row=g.row[i],
                            why="The consumer raises a heartbeat event (usually an EMCY 0x8130 "
                            "and a fault reaction); check the producer and the consumer time "
                            "in 0x1016.",
                        )

    def finish(self, ctx: Context) -> None:
        timing = ctx.timing
        for node, last in sorted(self.last_seen.items()):
            changes = ctx.config.changes(node, 0x1017, 0x1017)
            end = ctx.t_end if ctx.t_end is not None else last
            due, period, start = self._deadline(ctx, node, last, changes, end)
            t, gaps = timing.all_gaps("heartbeat", node)
            if node in self.unjudged and gaps.size >= 5:
                median = float(np.median(gaps)) * 1000.0
                limit = max(2.0, 1 + self.tolerance) * median / 1000.0
                unjudged = np.isin(t, np.concatenate(self.unjudged[node]))
                bad = np.flatnonzero((gaps > limit) & unjudged)
                for i in self.capped(bad, t[bad], node, 0x700 + node).tolist():
                    self.emit(
                        t[i],
                        node,
                        0x700 + node,
                        f"heartbeat dropout: no heartbeat for {ms(gaps[i])} ms from {ctx.rel(t[i])} "
                        "(period inferred from the median gap: 0x1017 not known at that time)",
                        ms(gaps[i]),
                        round(median, 3),
                        severity="warning",
                    )
                if period is None:  # not known at the end either: the median says when
                    due, period = start + limit, median
            if period and ctx.t_end is not None and ctx.t_end > due:
                self.emit(
                    start + period / 1000.0,
                    node,
                    0x700 + node,
                    f"heartbeat stopped: last one at {ctx.rel(last)}, log goes on for "
                    f"{ms(ctx.t_end - last)} ms",
                    ms(ctx.t_end - last),
                    round(period, 3),
                    why="The node fell silent (power, reset loop, bus-off or crash); check its supply "
                    "and whether it went bus-off (error frames just before).",
                )
