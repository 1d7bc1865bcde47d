"""`cananalyze check LOG`: run the rules, print findings, exit 0 (pass), 1 (violations), 2 (bad input)."""

from __future__ import annotations

import argparse
import sys

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, options, report_problems

# The checker, readers and decoder are imported in run(): `cananalyze --help` stays light.


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "check",
        help="check a log against CANopen rules and assertions (CI-friendly)",
        description="Check timing and conformance of a CANopen log; exit 0 when every "
        "enabled rule passes, 1 on violations, 2 on bad input.",
    )
    options_.add(p, *options_.INPUT, "rules", "junit", "json", "html", "timing", extra_names=DBC)
    options_.add(p, "no_color", *options_.FILTERS, "bitrate", "title", "quiet")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.cli.common import run_with_progress
    from cananalyze.outputs.findings import FindingsSink
    from cananalyze.pipeline import build_checker, build_decoder, open_source

    opts = options(args, checks=True, timing=bool(args.timing))
    checker = build_checker(opts)  # a bad rules file fails before the log is read
    source = open_source(args.log, opts)
    decoder = build_decoder(opts, checker)
    report = FindingsSink(
        sys.stdout,
        args.junit,
        args.json,
        timing=args.timing,
        no_color=args.no_color,
        html=args.html,
    )
    sinks: list = [report]
    if args.html:
        from cananalyze.outputs.report.sink import ReportSink

        # before the findings: the page exists when the JUnit file names it
        sinks.insert(0, ReportSink(args.html, bitrate=args.bitrate, title=args.title))
    try:
        run_with_progress(source, decoder, sinks, opts, quiet=args.quiet)
    finally:
        report_problems(source.problems)
    return report.exit_code
