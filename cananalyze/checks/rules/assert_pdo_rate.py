"""Assertion: a PDO's mean rate over the log is between min_hz and max_hz."""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule


class AssertPdoRate(Rule):
    name = "assert_pdo_rate"
    why = "The PDO rate differs from what the test requires; check the transmission type, event timer and SYNC."

    def __init__(
        self, cob_id: int, min_hz: float = 0.0, max_hz: float = float("inf"), **kw
    ) -> None:
        super().__init__(**kw)
        self.cob = int(cob_id)
        self.lo, self.hi = float(min_hz), float(max_hz)
        self.subjects.add(self.cob)

    def present(self, checker) -> bool:
        """Whether this bus carried the PDO (several buses: `engine.whole_log`)."""
        return checker.timing.count["pdo"].get(self.cob, 0) > 0

    def finish(self, ctx: Context) -> None:
        rate = ctx.timing.rate_hz("pdo", self.cob)
        if rate is None or not self.lo <= rate <= self.hi:
            got = "absent" if rate is None else f"{rate:.3f} Hz"
            sp = ctx.timing.span["pdo"].get(self.cob)
            self.emit(
                sp[0] if sp else (ctx.t_end or 0.0),
                None,
                self.cob,
                f"PDO 0x{self.cob:03X} rate {got}, required {self.lo:g}..{self.hi:g} Hz",
                None if rate is None else round(rate, 3),
                [self.lo, self.hi],
            )
