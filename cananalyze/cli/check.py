"""`cananalyze check LOG`: run the rules, print findings, exit 0 (pass), 1 (violations), 2 (bad input)."""

from __future__ import annotations

import argparse
import sys

from cananalyze.cli.common import add_filter_options, add_input_options, options, report_problems

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
    p.add_argument("--html", metavar="FILE", help="also write the HTML report (as `report`)")
    p.add_argument("--timing", action="store_true", help="also print the timing analysis")
    p.add_argument("--no-color", action="store_true", help="no ANSI colours even on a terminal")
    add_filter_options(p)
    from cananalyze.cli.report import add_html_options

    add_html_options(p)
    add_progress_option(p)
    p.set_defaults(func=run)


def add_progress_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")


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
