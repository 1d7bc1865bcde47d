"""Assertion: node N sends its heartbeat every P ms within a tolerance (both too slow and too fast)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cananalyze.checks.gaps import Gaps
from cananalyze.checks.rule import Context, Rule, ms

# The most (assertions x heartbeats) compared in one numpy call by `together`: a node
# asserted with 50,000 different periods in a batch of 262,144 heartbeats is compared a
# few hundred thousand cells at a time, not in one 13 GB table.
_CELLS = 1 << 20


class AssertHeartbeat(Rule):
    name = "assert_heartbeat"
    why = "The heartbeat period differs from what the test requires; check 0x1017 and the node's timing."

    def __init__(self, node: int, period_ms: float, **kw) -> None:
        super().__init__(**kw)
        self.node = int(node)
        self.period = float(period_ms)
        self.seen = False
        self.subjects.add(self.node)

    def _limits(self) -> tuple[float, float]:
        """The period in seconds and the largest deviation from it still within tolerance."""
        p = self.period / 1000.0
        return p, p * self.tolerance

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("heartbeat")
        for node, sl in g.groups():
            if node != self.node:
                continue
            self.seen = True
            gap = g.gap
            p, most = self._limits()
            bad = np.flatnonzero(np.abs(gap[sl] - p) > most) + sl.start
            self._judge(g, gap, bad)

    def _judge(self, g: Gaps, gap: np.ndarray, bad: np.ndarray) -> None:
        """Findings for the heartbeats at `bad` (indices into the gap table `g`)."""
        node = self.node
        for i in self.capped(bad, g.t[bad], node, 0x700 + node).tolist():
            self.emit(
                g.t[i],
                node,
                0x700 + node,
                f"heartbeat gap {ms(gap[i])} ms, required "
                f"{self.period:g} ms ± {self.tolerance:.0%}",
                ms(gap[i]),
                self.period,
                row=g.row[i],
                basis="the rules file's assert",
            )

    @classmethod
    def together(cls, rules: list[AssertHeartbeat]) -> Callable[[Context], None]:
        """All of a Checker's heartbeat assertions as one processor (`Rule.together`):
        indexed by node, so a batch touches only the assertions on the nodes it carries,
        and the assertions on one node with the same period and tolerance share one
        comparison (a rules file may repeat one thousands of times). Each assertion
        still emits its own findings, as its `process` would."""
        by_node: dict[int, dict[tuple[float, float], list[AssertHeartbeat]]] = {}
        every: dict[int, list[AssertHeartbeat]] = {}
        for r in rules:
            by_node.setdefault(r.node, {}).setdefault(r._limits(), []).append(r)
            every.setdefault(r.node, []).append(r)
        table = {
            node: (
                np.array([p for p, _ in same], np.float64),
                np.array([most for _, most in same], np.float64),
                list(same.values()),
                every[node],
            )
            for node, same in by_node.items()
        }
        seen: set[int] = set()

        def process(ctx: Context) -> None:
            g = ctx.gaps("heartbeat")
            gap = None
            for node, sl in g.groups():
                asserted = table.get(node)
                if asserted is None:
                    continue
                period, most, groups, every = asserted
                if node not in seen:
                    seen.add(node)
                    for r in every:
                        r.seen = True
                if gap is None:
                    gap = g.gap
                here = gap[sl]
                step = max(1, _CELLS // max(1, here.size))
                for lo in range(0, len(groups), step):
                    hi = lo + step
                    off = np.abs(here[None, :] - period[lo:hi, None]) > most[lo:hi, None]
                    for k in np.flatnonzero(off.any(axis=1)).tolist():
                        bad = np.flatnonzero(off[k]) + sl.start
                        for r in groups[lo + k]:
                            r._judge(g, gap, bad)

        return process

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
