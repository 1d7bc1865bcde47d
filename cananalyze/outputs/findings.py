"""`check`'s report as a sink: the findings in time order, the verdict, JUnit and JSON files.

The findings are the ones the Checker put on the decoded batches, after the
pipeline's filters, so `check --json`, JUnit, the findings table of `export` and
`load().findings` hold the same rows, every one. Only the terminal is capped (20 per
rule and node/COB-ID, with a count of the rest); end-of-log findings always show.
"""

from __future__ import annotations

import sys
from typing import TextIO

from ..checks.finding import Finding
from . import colour
from .junit import format_finding, write_findings_json, write_junit
from .sink import Sink

TERMINAL_CAP = 20  # findings printed per rule and node/COB-ID; the files hold every one


def terminal_cap(findings: list[Finding], cap: int) -> tuple[list[Finding], dict]:
    """The findings a terminal shows: the first `cap` per rule and node/COB-ID, and every
    end-of-log one (errors still active, a node that stopped: counted apart, never
    hidden); for the rest, per key, (first hidden, how many hidden, how many in all)."""
    count: dict[tuple, int] = {}
    for f in findings:
        key = (f.rule, f.node, f.cob_id, f.at_end)
        count[key] = count.get(key, 0) + 1
    seen: dict[tuple, int] = {}
    shown: list[Finding] = []
    hidden: dict[tuple, list] = {}
    for f in findings:
        key = (f.rule, f.node, f.cob_id, f.at_end)
        seen[key] = seen.get(key, 0) + 1
        if seen[key] <= cap or f.at_end:
            shown.append(f)
        elif key in hidden:
            hidden[key][1] += 1
        else:
            hidden[key] = [f, 1, count[key]]
    return shown, {k: tuple(v) for k, v in hidden.items()}


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
        self.findings: list[Finding] = []

    def open(self, run) -> None:
        super().open(run)
        if self.junit or self.json_file:
            from .atomic import check_writable

            for dest in (self.junit, self.json_file):
                if dest:
                    check_writable(dest)

    def write(self, batch) -> None:
        self.findings.extend(batch.findings)

    @property
    def failing(self) -> list[Finding]:
        return [f for f in self.findings if f.fails]

    @property
    def exit_code(self) -> int:
        """0: every enabled rule passed, 1: violations (info findings do not fail)."""
        return 1 if self.failing else 0

    def close(self) -> None:
        findings = sorted(self.findings, key=lambda f: f.t)
        self.findings = findings
        checker = self.run.checker
        rules = checker.rules if checker is not None else []
        if not self.quiet:
            out = self.out or sys.stdout
            on = colour.use_colour(out, self.no_color)
            shown, hidden = terminal_cap(findings, self.cap)
            for f in shown:
                print(
                    colour.paint(format_finding(f), colour.SEVERITY.get(f.severity, ""), on),
                    file=out,
                )
            for (rule, node, cob, _), (first, n, total) in hidden.items():
                where = ("node -" if node is None else f"node {node}") + (
                    "" if cob is None else f" 0x{cob:03X}"
                )
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
                    print("\n".join(checker.timing.lines(checker.nmt, 0.0)), file=out)
                else:
                    print("\n".join(checker.timing.lines(checker.nmt, checker.t0)), file=out)
            failing = len(self.failing)
            names = ", ".join(r.name for r in rules)
            verdict = (
                f"{len(rules)} rules ({names}): {failing} violation(s), "
                f"{len(findings) - failing} note(s)"
            )
            print(colour.paint(verdict, colour.SEVERITY["error"] if failing else "", on), file=out)
        if self.junit:
            props = {"cananalyze.report": str(self.html)} if self.html else None
            write_junit(self.junit, rules, findings, props)
        if self.json_file:
            write_findings_json(self.json_file, findings)
