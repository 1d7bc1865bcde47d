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
    from ..checks.build import attach_checker
    from ..io.source import open_log
    from ..outputs.junit import format_finding, write_findings_json, write_junit
    from .pipeline import build_decoder

    decoder = build_decoder(args)
    checker = attach_checker(decoder, args.rules)
    source = open_log(args.log, strict=args.strict, fmt=args.input_format)
    try:
        for fb in source.batches():
            decoder.decode(fb)
        decoder.finish()
    finally:
        report_problems(source.problems)
    out = sys.stdout
    for f in sorted(checker.findings, key=lambda f: f.t):
        print(format_finding(f), file=out)
    if args.timing:
        print("\n".join(checker.timing.lines(checker.nmt, checker.t0)), file=out)
    failing = [f for f in checker.findings if f.fails]
    names = ", ".join(r.name for r in checker.rules)
    print(
        f"{len(checker.rules)} rules ({names}): {len(failing)} violation(s), "
        f"{len(checker.findings) - len(failing)} note(s)",
        file=out,
    )
    if args.junit:
        write_junit(args.junit, checker.rules, checker.findings)
    if args.json:
        write_findings_json(args.json, checker.findings)
    return 1 if failing else 0
