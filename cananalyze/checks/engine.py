"""Checker: the processor that runs the timing analysis and every enabled rule on each batch.

Findings go into `batch.findings` as columns (`FindingColumns`, each at its row, so
`decode --format jsonl` streams them among the frames) and, unless built with
`keep_findings=False`, into `self.findings` for load(), `check` and the Python assertions. An
export takes every finding from the batches: kept here too, a 50M-frame log's
findings were held to the end for nobody.

A log without timestamps (candump screen output: every frame at one time) is told
once, its timing rules are skipped, and the order-based rules (PDO before start,
unexpected boot-up, SDO protocol, SYNC counter) judge it by line order: the rules see
each frame's line as its time. Live, `tick(now)` lets the deadline rules report a
silence while it lasts, not when the next frame (or Ctrl-C) ends it.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable

import numpy as np

from cananalyze.checks.config import ConfigSource
from cananalyze.checks.rule import Context, GapState, Rule
from cananalyze.checks.timing import Timing
from cananalyze.core.finding import Finding
from cananalyze.core.finding_columns import NONE, FindingColumns
from cananalyze.core.frames import FrameBatch
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.nmt_state import NmtStates

UNTIMED = "timestamps"  # the rule name of the one "no timestamps" finding


class Checker:
    def __init__(
        self,
        rules: list[Rule] | None = None,
        config: ConfigSource | None = None,
        keep_findings: bool = True,
    ) -> None:
        if rules is None:
            from cananalyze.checks.registry import default_rules

            rules = default_rules()
        self.rules = rules
        # the rules with findings since the last collection (Rule._tell), and where each
        # stands in `rules`: a batch's findings are taken in rule order from those alone
        self._emitted: list[Rule] = []
        self._position = {id(r): k for k, r in enumerate(rules)}
        for rule in rules:
            rule._board = self._emitted
        self._plans: dict[bool, tuple[list, list]] = {}  # timed or not: see _plan
        if config is None:  # nothing declared and no log followed: every value unknown
            from cananalyze.checks.model_config import ModelConfig
            from cananalyze.decode.model import NetworkModel

            config = ModelConfig(NetworkModel())
        self.config: ConfigSource = config
        self.nmt = NmtStates()
        # every gap is kept only for the tables a rule reads after the fact (flat memory otherwise)
        self.timing = Timing(keep={n for r in rules for n in getattr(r, "needs_gaps", ())})
        # False: findings only in the batches (self.findings unreadable)
        self.keep_findings = keep_findings
        self._found: list[FindingColumns] = []  # per batch (self.findings: all)
        self._gaps = GapState()
        self.t_last: float | None = None
        self.t0: float | None = None  # first frame of the log: findings read time from here
        # None until a batch of two frames or more says: False for a log without timestamps
        self.timed: bool | None = None
        self._view_t = np.zeros(0)  # the lines of the last batch the rules saw
        self.findings_untimed: Finding | None = None
        self._order = 0  # frames seen (the line of an untimed frame without a line number)
        self._last_line = 0
        # several buses (pipeline.Decoder): one Checker per bus, its findings naming it
        self.bus: str | None = None
        self.first_bus = True  # the one that tells a log without timestamps (once per log)
        self.others: list[Checker] = []  # the other buses' checkers (this one: the first's)
        # (path, its `network:` section's settings or None) when the rules came from a rules
        # file (checks/build.py): the pipeline's declarations take the section from here,
        # so the file is read once (a 2 MB file costs seconds to parse)
        self.rules_file: tuple[str, dict | None] | None = None

    def name_bus(self, name: str) -> None:
        """Several buses: this Checker judges bus `name`; what it found so far (before a
        second bus was seen) is that bus's."""
        self.bus = name
        for found in self._found:
            found.bus[found.rule != UNTIMED] = name  # "no timestamps" is the whole log's
        if self._found:
            self._sync_objects(self.findings)

    def pristine(self) -> Callable[[], Checker]:
        """A maker of Checkers with this one's rules as they are now (before any frame):
        another bus's, judged apart."""
        rules = copy.deepcopy(self.rules, {id(self._emitted): []})  # not this one's board
        with_stats = self.timing.with_stats

        def make() -> Checker:
            fresh = Checker(copy.deepcopy(rules), self.config, self.keep_findings)
            fresh.timing.with_stats = with_stats
            fresh.rules_file = self.rules_file
            return fresh

        return make

    @property
    def active(self) -> list[Rule]:
        """The rules that judge this log: not the timing rules on a log without times."""
        if self.timed is False:
            return [r for r in self.rules if not r.timing]
        return self.rules

    def _plan(self) -> tuple[list[Callable[[Context], None]], list[tuple[Rule, object]]]:
        """How the active rules judge a batch: the processors to call in order, and per
        rule the processor called at its place (None: none). A rule that does not
        override `process` has none (judged at the end only); the rules of a class with
        `together` share one processor, at the place of the first of them."""
        key = self.timed is False
        plan = self._plans.get(key)
        if plan is None:
            members: dict[type, list[Rule]] = {}
            places: list[tuple[Rule, object]] = []
            for rule in self.active:
                kind = type(rule)
                if kind.process is Rule.process:
                    places.append((rule, None))
                elif kind.together is None:
                    places.append((rule, rule.process))
                elif kind in members:
                    members[kind].append(rule)
                    places.append((rule, None))
                else:
                    members[kind] = [rule]
                    places.append((rule, kind))
            made = {kind: kind.together(group) for kind, group in members.items()}
            places = [(r, made[step] if isinstance(step, type) else step) for r, step in places]
            plan = self._plans[key] = ([step for _, step in places if step], places)
        return plan

    def _context(self, batch: DecodedBatch, t_end: float | None = None) -> Context:
        if self.t0 is None and len(batch):
            self.t0 = float(batch.frames.t[0])
        t0 = self.t0
        if self.timed is False:
            batch = self._by_order(batch)
            t0 = 0.0
        ctx = Context(batch, self.config, self.nmt, self._gaps, t_end, t0, self.timed is not False)
        ctx.timing = self.timing
        return ctx

    def _decide(self, batch: DecodedBatch) -> None:
        """Whether the log has timestamps, from its first batch of two frames or more."""
        t = batch.frames.t
        if self.timed is not None or t.size < 2:
            return
        self.timed = bool(t.max() > t.min())
        if not self.timed and self.first_bus:
            self.timing.with_stats = False  # gaps between lines are no periods
            skipped = ", ".join(r.name for r in self.rules if r.timing)
            self.findings_untimed = Finding(
                float(t[0]),
                UNTIMED,
                "info",
                None,
                None,
                f"no timestamps: timing rules skipped ({skipped}); the others judged by line order",
                "no timestamps",
                "timestamps",
                "Every frame of the log has the same time (screen output of candump without "
                "-t, or a logger without a clock): periods, timeouts and deadlines cannot be "
                "judged. Record with timestamps (candump -l or -t a) to check them.",
                line=int(batch.frames.line[0]) or 1,
            )

    def _by_order(self, batch: DecodedBatch) -> DecodedBatch:
        """The batch as the rules see it in a log without times: each frame's time is its
        line (file order), or its position when the reader gives no line numbers."""
        fb = batch.frames
        n = len(fb)
        if n == 0:
            return batch
        line = fb.line.astype(np.float64)
        if not (line[0] > self._last_line and (n < 2 or bool(np.all(np.diff(line) > 0)))):
            line = np.arange(self._order + 1, self._order + n + 1, dtype=np.float64)
        self._order += n
        self._last_line = int(line[-1])
        frames: FrameBatch = dataclasses.replace(fb, t=line)
        self._view_t = line
        # the drive's changes carry their frame's time: the line too (row len(fb): the end)
        drive = [c._replace(t=float(line[min(c.row, n - 1)])) for c in batch.drive]
        return dataclasses.replace(batch, frames=frames, drive=drive)

    def process(self, batch: DecodedBatch) -> None:
        if len(batch) == 0 and not batch.records:  # (findings: the Checker's own)
            return
        self._decide(batch)
        ctx = self._context(batch)
        if len(batch):
            self.nmt.update(ctx.batch, ctx)
            self.t_last = float(ctx.batch.frames.t[-1])
        self.timing.update(ctx)
        for step in self._plan()[0]:
            step(ctx)
        self._collect(batch)

    def tick(self, batch: DecodedBatch, now: float) -> None:
        """Live, after a batch: the deadline rules report what is overdue at `now` (the
        bus's clock: the latest frame's time, or past it on the wall clock when no frame
        comes) into `batch` (an empty one the pipeline delivers to the sinks), before the
        frame that ends the silence comes; the records time completed (SDO timeouts) are
        judged as a batch's."""
        if self.timed is False or self.t_last is None:
            return
        ctx = self._context(batch)
        ctx.t_bus = self.t_last
        if batch.records:
            for step in self._plan()[0]:
                step(ctx)
        for rule in self.active:
            if type(rule).tick is not Rule.tick:  # (the base tick reports nothing)
                rule.tick(ctx, now)
        self._collect(batch)

    def finish(self, batch: DecodedBatch) -> None:
        ctx = self._context(batch, t_end=self.t_last)
        self.timing.update(ctx)
        for rule in self.rules:
            rule.ending = True
        for rule, step in self._plan()[1]:
            if step is not None:
                step(ctx)  # records that only the end completes (pending SDO timeouts)
            if not rule.elsewhere:
                rule.finish(ctx)
            rule.close(self.t_last or 0.0)
        self._collect(batch, at_end=True)

    def _collect(self, batch: DecodedBatch, at_end: bool = False) -> None:
        parts: list[FindingColumns] = []
        if self.findings_untimed is not None:
            parts.append(FindingColumns.of([self.findings_untimed]))
            self.findings_untimed = None
        emitted, self._emitted[:] = list(self._emitted), []
        if at_end or any(id(r) not in self._position for r in emitted):
            rules = self.rules  # once per log: every rule (also one another Checker told)
        else:
            rules = sorted(emitted, key=lambda r: self._position[id(r)])
        single: list[Finding] = []  # consecutive rules' one-by-one findings: one part
        for rule in rules:
            for part in rule.taken():
                if isinstance(part, list):
                    single += part
                    continue
                if single:
                    parts.append(FindingColumns.of(single))
                    single = []
                parts.append(part)
        if single:
            parts.append(FindingColumns.of(single))
        new = FindingColumns.concat(parts)
        if not len(new):
            return
        if self.timed is False:  # the rules' times are lines: back to the log's time
            t_log = self.t0 if self.t0 is not None else 0.0
            lines = self._view_t
            mine = new.rule != UNTIMED
            fix = mine & (new.t < 1) & (new.row >= 0) & (new.row < lines.size) & (not at_end)
            new.t[fix] = lines[new.row[fix]]  # an SDO record's own time: the log's, not a line
            new.line[mine] = np.where(new.t[mine] >= 1, new.t[mine].astype(np.int64), NONE)
            new.t[mine] = t_log
        t0 = self.t0
        new.t_rel = new.t - (t0 if t0 is not None else new.t)
        if at_end:
            new.row[:] = 0  # the end batch has no rows: after every frame
        if self.bus is not None:
            new.bus[new.rule != UNTIMED] = self.bus  # "no timestamps" is the whole log's
        self._sync_objects(new)
        new = new.sort()
        batch.findings = FindingColumns.concat([batch.findings, new])
        if self.keep_findings:
            self._found.append(new)

    @staticmethod
    def _sync_objects(new: FindingColumns) -> None:
        """The rows emitted alone keep their Finding: give it the columns' values."""
        for i in np.flatnonzero(np.not_equal(new.obj, None)).tolist():
            f = new.obj[i]
            line = int(new.line[i])
            f.t, f.line, f.row = float(new.t[i]), (None if line == NONE else line), int(new.row[i])
            f.t_rel, f.at_end = float(new.t_rel[i]), bool(new.at_end[i])
            f.bus = new.bus[i]

    @property
    def findings(self) -> FindingColumns:
        """Every finding so far, batch by batch (each batch's by time); with several
        buses, every bus's, by time."""
        if not self.keep_findings:
            raise RuntimeError(
                "this Checker was built with keep_findings=False: read batch.findings"
            )
        if len(self._found) > 1:
            self._found = [FindingColumns.concat(self._found)]
        mine = self._found[0] if self._found else FindingColumns()
        if not self.others:
            return mine
        found = FindingColumns.concat([mine, *(c.findings for c in self.others)])
        return found.take(np.argsort(found.t, kind="stable")) if len(found) > 1 else found

    def report(self) -> dict:
        return self.timing.report(self.nmt)

    def timing_lines(self, t0: float | None) -> list[str]:
        """`check --timing`'s lines: this bus's, or each bus's under its name."""
        if not self.others:
            return self.timing.lines(self.nmt, t0, self.timed is not False)
        out: list[str] = []
        for c in (self, *self.others):
            lines = c.timing.lines(c.nmt, t0, c.timed is not False)
            if lines:  # a bus with nothing timed (no CANopen on it) gets no empty heading
                out += [f"{c.bus}:", *("  " + line for line in lines)]
        return out


def whole_log(checkers: list[Checker]) -> None:
    """Several buses, before their end: an assertion about the whole log (the rules
    file's `assert:` list: node 5 boots, sends heartbeats, signal seen, PDO rate) is
    told absent once, by the first bus, and only when no bus saw its subject; the
    buses that saw it judge it there, the others say nothing."""
    for k, rule in enumerate(checkers[0].rules):
        if not hasattr(rule, "present"):
            continue
        seen = [c.rules[k].present(c) for c in checkers]
        for c, here in zip(checkers, seen, strict=True):
            c.rules[k].elsewhere = not here and (any(seen) or c is not checkers[0])
