"""`cananalyze check LOG`: run the rules, print findings, exit 0 (pass), 1 (violations), 2 (bad input)."""

from __future__ import annotations

import argparse
import sys

from .common import add_input_options, report_problems

# The checker, readers and decoder are imported in run(): `cananalyze --help` stays light.


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="check a log against CANopen rules and assertions (CI-friendly)",
        description="Check timing and conformance of a CANopen log; exit 0 when every "
        "enabled rule passes, 1 on violations, 2 on bad input.",
    )
    add_input_options(p)
    p.add_argument("--rules", metavar="FILE", help="rules file (YAML, see docs/rules-file.md)")
    p.add_argument("--junit", metavar="FILE", help="write a JUnit XML report")
    p.add_argument("--json", metavar="FILE", help="write the findings as a JSON list")
    p.add_argument("--timing", action="store_true", help="also print the timing analysis")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..checks.build import attach_checker, build_checker
    from ..io.prefetch import prefetch
    from ..io.source import open_log
    from .pipeline import build_decoder

    checker = build_checker(args.rules)  # a bad rules file fails before the log is read
    source = open_log(args.log, strict=args.strict, fmt=args.input_format)
    decoder = build_decoder(args)
    attach_checker(decoder, checker)
    try:
        for fb in prefetch(source.batches()):  # read ahead on the other core
            decoder.decode(fb)
        decoder.finish()
    finally:
        report_problems(source.problems)
    return check_result(checker, args.junit, args.json, timing=args.timing)


def check_result(
    checker, junit: str | None = None, json_file: str | None = None, timing: bool = False, out=None
) -> int:
    """Findings in time order, the verdict line, the reports; returns the exit code (0 or 1)."""
    from ..outputs.junit import format_finding, write_findings_json, write_junit

    out = out or sys.stdout
    for f in sorted(checker.findings, key=lambda f: f.t):
        print(format_finding(f), file=out)
    if timing:
        print("\n".join(checker.timing.lines(checker.nmt, checker.t0)), file=out)
    failing = [f for f in checker.findings if f.fails]
    names = ", ".join(r.name for r in checker.rules)
    print(
        f"{len(checker.rules)} rules ({names}): {len(failing)} violation(s), "
        f"{len(checker.findings) - len(failing)} note(s)",
        file=out,
    )
    if junit:
        write_junit(junit, checker.rules, checker.findings)
    if json_file:
        write_findings_json(json_file, checker.findings)
    return 1 if failing else 0
