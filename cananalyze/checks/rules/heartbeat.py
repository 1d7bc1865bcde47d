"""Heartbeat rules: dropouts against 0x1017, heartbeats that stop, consumer time expiry.

Without a configured producer time the expected period is inferred from the
node's median gap, and findings say so.
"""

from __future__ import annotations

import numpy as np

from ..rule import Context, Rule, ms


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
        self.configured: set[int] = set()
        # node -> time of its last heartbeat judged without a configured period (no 0x1017
        # known yet, e.g. written by SDO later in the log): finish() infers the period for these
        self.unjudged: dict[int, float] = {}

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("heartbeat")
        if g.key.size == 0:
            return
        gap = g.gap
        consumers = self._consumers(ctx)
        for node, sl in g.groups():
            self.subjects.add(node)
            self.last_seen[node] = float(g.t[sl.stop - 1])
            period = self._periods(ctx, node, g.t[sl])
            unknown = np.isnan(period)
            if unknown.any():
                self.unjudged[node] = float(g.t[sl][unknown][-1])
            if not unknown.all():
                self.configured.add(node)
                limit = period * (1 + self.tolerance) / 1000.0
                bad = np.flatnonzero(gap[sl] > limit) + sl.start
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
            for consumer, limit_ms in consumers.get(node, ()):
                for i in (np.flatnonzero(gap[sl] > limit_ms / 1000.0) + sl.start).tolist():
                    self.emit(
                        g.prev[i] + limit_ms / 1000.0,
                        node,
                        0x700 + node,
                        f"node {consumer}'s heartbeat consumer time for node {node} expired "
                        f"(gap {ms(gap[i])} ms)",
                        ms(gap[i]),
                        limit_ms,
                        row=g.row[i],
                        why="The consumer raises a heartbeat event (usually an EMCY 0x8130 and a fault "
                        "reaction); check the producer and the consumer time in 0x1016.",
                    )

    @staticmethod
    def _periods(ctx: Context, node: int, t: np.ndarray) -> np.ndarray:
        """0x1017 in force at each heartbeat (NaN: unknown or 0). One lookup per batch unless
        the value changes inside it (an SDO write mid-batch): then one per heartbeat, rarely."""

        def at(x: float) -> float:
            v = ctx.config.heartbeat_ms(node, float(x))
            return float(v) if v else np.nan

        first, last = at(t[0]), at(t[-1])
        if first == last or (np.isnan(first) and np.isnan(last)):
            return np.full(t.size, first)
        return np.array([at(x) for x in t.tolist()])

    def _consumers(self, ctx: Context) -> dict[int, list[tuple[int, float]]]:
        out: dict[int, list[tuple[int, float]]] = {}
        for consumer in range(1, 128):
            for producer, limit in ctx.config.heartbeat_consumers(consumer, ctx.t_first).items():
                if limit:
                    out.setdefault(producer, []).append((consumer, limit))
        return out

    def finish(self, ctx: Context) -> None:
        timing = ctx.timing
        for node, last in sorted(self.last_seen.items()):
            period = ctx.config.heartbeat_ms(node, last)
            inferred = False
            t, gaps = timing.all_gaps("heartbeat", node)
            if not period and gaps.size < 5:
                continue  # too few heartbeats to infer a period from
            if node in self.unjudged and gaps.size >= 5:
                median = float(np.median(gaps)) * 1000.0
                if not period:
                    period, inferred = median, True
                limit = max(2.0, 1 + self.tolerance) * median / 1000.0
                bad = np.flatnonzero((gaps > limit) & (t <= self.unjudged[node]))
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
            limit = (
                period * (max(2.0, 1 + self.tolerance) if inferred else 1 + self.tolerance) / 1000.0
            )
            if ctx.t_end is not None and ctx.t_end - last > limit:
                self.emit(
                    last + period / 1000.0,
                    node,
                    0x700 + node,
                    f"heartbeat stopped: last one at {ctx.rel(last)}, log goes on for "
                    f"{ms(ctx.t_end - last)} ms",
                    ms(ctx.t_end - last),
                    round(period, 3),
                    why="The node fell silent (power, reset loop, bus-off or crash); check its supply "
                    "and whether it went bus-off (error frames just before).",
                )
