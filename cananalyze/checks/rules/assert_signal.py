"""Assertion: a decoded PDO signal of a node stays within [min, max] (from batch.signals)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cananalyze.checks.rule import Context, Rule


class AssertSignal(Rule):
    name = "assert_signal"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = "A process value left its allowed range; check the sensor, its scaling and the process itself."

    def __init__(
        self, node: int, signal: str, min: float = -np.inf, max: float = np.inf, **kw
    ) -> None:  # noqa: A002
        super().__init__(**kw)
        self.node, self.signal = int(node), str(signal)
        self.lo, self.hi = float(min), float(max)
        self.seen = False
        self.subjects.add(self.node)

    def process(self, ctx: Context) -> None:
        for block in ctx.batch.signals:
            if block.node == self.node:
                self._judge(ctx, block, {})

    @classmethod
    def together(cls, rules: list[AssertSignal]) -> Callable[[Context], None]:
        """All of a Checker's signal assertions as one processor (`Rule.together`): a
        block of decoded signals is shown only to the assertions on its node, and the
        assertions of one signal with the same range share one comparison."""
        by_node: dict[int, list[AssertSignal]] = {}
        for r in rules:
            by_node.setdefault(r.node, []).append(r)

        def process(ctx: Context) -> None:
            for block in ctx.batch.signals:
                shared: dict = {}
                for r in by_node.get(block.node, ()):
                    r._judge(ctx, block, shared)

        return process

    def _judge(self, ctx: Context, block, shared: dict) -> None:
        """Findings for one block of this node's signals; `shared`: the rows out of range
        per (signal, min, max), for the block's other assertions."""
        if self.signal not in block.columns:
            return
        self.seen = True
        key = (self.signal, self.lo, self.hi)
        if key not in shared:
            v = np.asarray(block.columns[self.signal], float)
            shared[key] = v, np.flatnonzero((v < self.lo) | (v > self.hi))
        v, bad = shared[key]
        if bad.size:
            for i in self.capped(bad, ctx.t[block.rows[bad]], self.node, block.cob_id).tolist():
                row = int(block.rows[i])
                self.emit(
                    ctx.t[row],
                    self.node,
                    block.cob_id,
                    f"{self.signal} = {v[i]:g} outside {self.lo:g}..{self.hi:g}",
                    float(v[i]),
                    [self.lo, self.hi],
                    row=row,
                )

    def present(self, checker) -> bool:
        """Whether this bus showed the subject (several buses: `engine.whole_log`)."""
        return self.seen

    def finish(self, ctx: Context) -> None:
        if not self.seen:
            self.emit(
                ctx.t_end or 0.0,
                self.node,
                None,
                f"signal {self.signal} of node {self.node} never seen",
                None,
                [self.lo, self.hi],
            )
