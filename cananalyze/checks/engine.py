"""Checker: the processor that runs the timing analysis and every enabled rule on each batch.

Findings go into `batch.records` at their row (so `decode --format jsonl` streams
them) and into `self.findings` for the CLI, JUnit and the Python assertions.
"""

from __future__ import annotations

from ..records import DecodedBatch
from .config import ConfigSource
from .finding import Finding
from .nmt_state import NmtStates
from .rule import Context, GapState, Rule
from .timing import Timing


class Checker:
    def __init__(self, rules: list[Rule] | None = None, config: ConfigSource | None = None) -> None:
        if rules is None:
            from .registry import default_rules

            rules = default_rules()
        self.rules = rules
        if config is None:  # nothing declared and no log followed: every value unknown
            from ..network.model import NetworkModel
            from .model_config import ModelConfig

            config = ModelConfig(NetworkModel())
        self.config: ConfigSource = config
        self.nmt = NmtStates()
        # every gap is kept only for the tables a rule reads after the fact (flat memory otherwise)
        self.timing = Timing(keep={n for r in rules for n in getattr(r, "needs_gaps", ())})
        self.findings: list[Finding] = []
        self._gaps = GapState()
        self.t_last: float | None = None
        self.t0: float | None = None  # first frame of the log: findings read time from here

    def _context(self, batch: DecodedBatch, t_end: float | None = None) -> Context:
        if self.t0 is None and len(batch):
            self.t0 = float(batch.frames.t[0])
        ctx = Context(batch, self.config, self.nmt, self._gaps, t_end, self.t0)
        ctx.timing = self.timing
        return ctx

    def process(self, batch: DecodedBatch) -> None:
        if len(batch) == 0 and not batch.records:
            return
        ctx = self._context(batch)
        if len(batch):
            self.nmt.update(batch)
            self.t_last = float(batch.frames.t[-1])
        self.timing.update(ctx)
        for rule in self.rules:
            rule.process(ctx)
        self._collect(batch)

    def finish(self, batch: DecodedBatch) -> None:
        ctx = self._context(batch, t_end=self.t_last)
        self.timing.update(ctx)
        for rule in self.rules:
            rule.process(ctx)  # records that only the end completes (pending SDO timeouts)
            rule.finish(ctx)
            rule.close(self.t_last or 0.0)
        self._collect(batch, at_end=True)

    def _collect(self, batch: DecodedBatch, at_end: bool = False) -> None:
        new: list[Finding] = []
        for rule in self.rules:
            new.extend(rule.take())
        new.sort(key=lambda f: f.t)
        for f in new:
            f.t_rel = f.t - (self.t0 if self.t0 is not None else f.t)
            batch.add_record(0 if at_end else f.row, f.record())
        batch.findings.extend(new)
        self.findings.extend(new)

    @property
    def failed(self) -> bool:
        return any(f.fails for f in self.findings)

    def report(self) -> dict:
        return self.timing.report(self.nmt)
