"""`check`'s report as a sink: the findings in time order, the verdict, JUnit and JSON files.

The findings are the ones the Checker put on the decoded batches, after the
pipeline's filters, so `check --json`, JUnit, the findings table of `export` and
`load().findings` hold the same rows, every one. Only the terminal is capped (20 per
rule and node/COB-ID, with a count of the rest); end-of-log findings always show.
"""

from __future__ import annotations

import sys
from typing import TextIO

import numpy as np

from cananalyze.core.atomic import Staged
from cananalyze.core.columns.order import first_seen_codes
from cananalyze.core.finding import Finding
from cananalyze.core.finding_columns import FindingColumns
from cananalyze.decode.node_load import NodeLoad, run_bitrate
from cananalyze.outputs import colour
from cananalyze.outputs.findings_json import findings_json_parts
from cananalyze.outputs.junit import format_rows, junit_xml_parts
from cananalyze.pipeline.sink import Sink

TERMINAL_CAP = 20  # findings printed per rule and node/COB-ID; the files hold every one


def terminal_cap(findings: FindingColumns, cap: int) -> tuple[np.ndarray, dict]:
    """The rows a terminal shows: the first `cap` per rule and node/COB-ID, and every
    end-of-log one (errors still active, a node that stopped: counted apart, never
    hidden); for the rest, per key, (first hidden, how many hidden, how many in all).

    Counted as columns: only each key's first hidden finding becomes a Finding object;
    the rows shown are printed from the columns (`junit.format_rows`)."""
    n = len(findings)
    if n == 0:
        return np.zeros(0, np.int64), {}
    rule_code, _ = first_seen_codes(findings.rule.tolist())
    # one integer per (rule, node, COB-ID, at end): node < 256, COB-ID < 2^30 (29-bit ids)
    keys = (rule_code << 40) | ((findings.node + 1) << 31) | ((findings.cob_id + 1) << 1)
    keys |= findings.at_end
    if np.not_equal(findings.bus, None).any():  # several buses: node 5 on each apart
        bus_code, buses = first_seen_codes(findings.bus.tolist())
        keys = keys * len(buses) + bus_code
    _, key_of, total = np.unique(keys, return_inverse=True, return_counts=True)
    key_of = key_of.reshape(-1)
    order = np.argsort(key_of, kind="stable")
    rank = np.empty(n, np.int64)
    starts = np.concatenate(([0], np.cumsum(total)[:-1]))
    rank[order] = np.arange(n) - np.repeat(starts, total)
    shown = (rank < cap) | findings.at_end
    hidden_first = np.flatnonzero(~shown & (rank == cap))  # each capped key's first hidden
    hidden: dict[tuple, tuple] = {}
    for i, f in zip(hidden_first.tolist(), findings.findings(hidden_first), strict=True):
        k = key_of[i]  # in the order each key's first hidden one comes
        hidden[(f.rule, f.node, f.cob_id, f.at_end, f.bus)] = (
            f,
            int(total[k]) - cap,
            int(total[k]),
        )
    return np.flatnonzero(shown), hidden


class FindingsSink(Sink):
    """Collects every finding; at close prints them (unless `quiet`) and writes the reports."""

    def __init__(
        self,
        out: TextIO | None = None,
        junit: str | None = None,
        json_file: str | None = None,
        timing: bool = False,
        no_color: bool = False,
        quiet: bool = False,
        html: str | None = None,
        cap: int = TERMINAL_CAP,
    ) -> None:
        self.cap = cap
        self.out = out
        self.junit = junit
        self.json_file = json_file
        self.timing = timing
        self.no_color = no_color
        self.quiet = quiet
        self.html = html  # the HTML report's path, named in the JUnit properties
        self._parts: list[FindingColumns] = []
        self.findings = FindingColumns()  # every finding, by time (at close)
        self._sorted = False  # findings is every part, sorted, its live rows read again
        self._staged: list[Staged] = []  # JUnit/JSON written, waiting for the commit
        self.load = NodeLoad()  # --timing: bus load per node, as `decode --summary`'s
        self.bitrate: int | None = None  # the run's (open)

    def open(self, run) -> None:
        super().open(run)
        self.bitrate = run_bitrate(run)
        if self.junit or self.json_file:
            from cananalyze.core.atomic import check_writable

            for dest in (self.junit, self.json_file):
                if dest:
                    check_writable(dest)

    def write(self, batch) -> None:
        if self.timing:
            self.load.add(batch)
        if len(batch.findings):
            self._parts.append(batch.findings)
            self._sorted = False

    def _gather(self) -> FindingColumns:
        """Every finding so far, by time (stable); the rows emitted alone read again from
        their Finding (live, a silence's finding is completed when it ends)."""
        if not self._parts and self._sorted:
            return self.findings
        found = FindingColumns.concat([self.findings, *self._parts])
        self._parts = []
        live = np.flatnonzero(np.not_equal(found.obj, None))
        if live.size:
            found.refresh(live)
        if found.t.size > 1 and (np.diff(found.t) < 0).any():
            found = found.take(np.argsort(found.t, kind="stable"))
        self.findings = found
        self._sorted = True
        return found

    @property
    def failing(self) -> list[Finding]:
        found = self._gather()
        return found.findings(np.flatnonzero(found.fails))

    @property
    def exit_code(self) -> int:
        """0: every enabled rule passed, 1: violations (info findings do not fail)."""
        return 1 if self._gather().fails.any() else 0

    def close(self) -> None:
        self.finish()
        self.commit()

    def finish(self) -> None:
        """The terminal's lines now; the JUnit and JSON files written beside their targets,
        put in place with the run's other outputs (`commit`), or dropped (`abort`)."""
        findings = self._gather()
        checker = self.run.checker
        rules = checker.rules if checker is not None else []
        if not self.quiet:
            out = self.out or sys.stdout
            on = colour.use_colour(out, self.no_color)
            shown, hidden = terminal_cap(findings, self.cap)
            severity = findings.column("severity")
            for i, line in zip(shown.tolist(), format_rows(findings, shown), strict=True):
                print(colour.paint(line, colour.SEVERITY.get(severity[i], ""), on), file=out)
            for (rule, _, cob, _, _), (first, n, total) in hidden.items():
                where = first.where + ("" if cob is None else f" 0x{cob:03X}")
                more = (
                    "--json and --junit list every one"
                    if self.junit or self.json_file
                    else ("--json FILE lists every one")
                )
                line = (
                    f"{first.t_rel or 0.0:+.3f} s {where} [{first.severity}] {rule}: {n} more "
                    f"like this not shown ({total} in all; {more})"
                )
                print(colour.paint(line, colour.SEVERITY.get(first.severity, ""), on), file=out)
            if self.timing and checker is not None:
                if checker.timed is False:
                    print("no timestamps: the times below are line numbers, no rates", file=out)
                    print("\n".join(checker.timing_lines(0.0)), file=out)
                else:
                    lines = checker.timing_lines(checker.t0)
                    lines += self.load.lines(self.bitrate, timed=True)
                    print("\n".join(lines), file=out)
            failing = int(findings.fails.sum())
            names = ", ".join(r.name for r in rules)
            verdict = (
                f"{len(rules)} rules ({names}): {failing} violation(s), "
                f"{len(findings) - failing} note(s)"
            )
            print(colour.paint(verdict, colour.SEVERITY["error"] if failing else "", on), file=out)
        if self.junit:
            props = {"cananalyze.report": str(self.html)} if self.html else None
            staged = Staged(self.junit)
            self._staged.append(staged)
            staged.write_text(junit_xml_parts(rules, findings, properties=props))
        if self.json_file:
            staged = Staged(self.json_file)
            self._staged.append(staged)
            staged.write_text(findings_json_parts(findings))

    def commit(self) -> None:
        for staged in self._staged:
            staged.commit()
        self._staged = []

    def abort(self) -> None:
        for staged in self._staged:
            staged.abort()
        self._staged = []
