"""Assertion: node N sends its heartbeat every P ms within a tolerance (both too slow and too fast)."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms


class AssertHeartbeat(Rule):
    name = "assert_heartbeat"
    why = "The heartbeat period differs from what the test requires; check 0x1017 and the node's timing."

    def __init__(self, node: int, period_ms: float, **kw) -> None:
        super().__init__(**kw)
        self.node = int(node)
        self.period = float(period_ms)
        self.seen = False
        self.subjects.add(self.node)

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("heartbeat")
        for node, sl in g.groups():
            if node != self.node:
                continue
            self.seen = True
            gap = g.gap[sl]
            p = self.period / 1000.0
            bad = np.flatnonzero(np.abs(gap - p) > p * self.tolerance) + sl.start
            for i in self.capped(bad, g.t[bad], node, 0x700 + node).tolist():
                self.emit(
                    g.t[i],
                    node,
                    0x700 + node,
                    f"heartbeat gap {ms(g.gap[i])} ms, required "
                    f"{self.period:g} ms ± {self.tolerance:.0%}",
                    ms(g.gap[i]),
                    self.period,
                    row=g.row[i],
                    basis="the rules file's assert",
                )

    def present(self, checker) -> bool:
        """Whether this bus showed the subject (several buses: `engine.whole_log`)."""
        return self.seen

    def finish(self, ctx: Context) -> None:
        if not self.seen:
            self.emit(
                ctx.t_end or 0.0,
                self.node,
                0x700 + self.node,
                f"no heartbeat from node {self.node}",
                0,
                self.period,
            )
