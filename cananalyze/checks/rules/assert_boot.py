"""Assertion: node N is operational within S seconds of each of its boot-ups."""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule
from cananalyze.protocol.nmt import OPERATIONAL


class AssertOperational(Rule):
    name = "assert_operational"
    why = "The node did not reach OPERATIONAL in time after booting; check the master's start-up sequence and SDO configuration."

    def __init__(self, node: int, within_s: float, **kw) -> None:
        super().__init__(**kw)
        self.node, self.within = int(node), float(within_s)
        self.subjects.add(self.node)

    def present(self, checker) -> bool:
        """Whether this bus showed the node boot (several buses: `engine.whole_log`)."""
        return "bootup" in checker.nmt.sources.get(self.node, [])

    def finish(self, ctx: Context) -> None:
        times = ctx.nmt.times.get(self.node, [])
        states = ctx.nmt.states.get(self.node, [])
        sources = ctx.nmt.sources.get(self.node, [])
        boots = [i for i, s in enumerate(sources) if s == "bootup"]
        if not boots:
            self.emit(
                ctx.t_end or 0.0,
                self.node,
                None,
                f"no boot-up of node {self.node} in the log",
                None,
                f"operational within {self.within:g} s of boot-up",
            )
        for i in boots:
            t_boot = times[i]
            op = next(
                (times[j] for j in range(i + 1, len(times)) if states[j] == OPERATIONAL), None
            )
            if op is None or op - t_boot > self.within:
                got = "never" if op is None else f"after {op - t_boot:.3f} s"
                self.emit(
                    t_boot,
                    self.node,
                    None,
                    f"node {self.node} operational {got} after its boot-up",
                    None if op is None else round(op - t_boot, 6),
                    self.within,
                )
