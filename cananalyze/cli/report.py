"""`cananalyze report LOG -o report.html`: the check's findings and the log's statistics
as one self-contained HTML page (exit codes as `check`: 0 pass, 1 violations, 2 bad input)."""

from __future__ import annotations

import argparse
import sys

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, options, report_problems


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="write an HTML report of a log: verdict, findings, nodes, plots",
        description="Check a log and write one self-contained HTML page (plots embedded, no "
        "network needed to open it); exit 0 when every rule passes, 1 on violations, 2 on "
        "bad input.",
    )
    options_.add(p, *options_.INPUT, extra_names=DBC)
    options_.add(p, "output", "rules", "bitrate", "title", required=("output",))
    options_.add(p, *options_.FILTERS, "quiet")
    options_.add(p, "against", "tolerance", "tolerance_ms", "reference_node")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.cli.common import run_with_progress
    from cananalyze.outputs.findings import FindingsSink
    from cananalyze.outputs.report.sink import ReportSink
    from cananalyze.pipeline import build_checker, build_decoder, open_source

    opts = options(args, checks=True)
    checker = build_checker(opts)  # a bad rules file fails before the log is read
    differences = _against(args) if args.against else None
    source = open_source(args.log, opts)
    decoder = build_decoder(opts, checker)
    verdict = FindingsSink(quiet=True)
    page = ReportSink(args.output, bitrate=args.bitrate, title=args.title, differences=differences)
    try:
        run_with_progress(source, decoder, [verdict, page], opts, quiet=args.quiet)
    finally:
        report_problems(source.problems)
    failing = len(verdict.failing)
    print(
        f"{args.output}: {failing} violation(s), {len(verdict.findings) - failing} note(s)",
        file=sys.stderr,
    )
    return verdict.exit_code


def _against(args: argparse.Namespace):
    """`diff LOG B`'s comparison (api/diff.py), of the whole log as `diff` reads it (the
    filters choose what the page shows, not what is compared): LOG is read once more."""
    from cananalyze.api import diff
    from cananalyze.api.capture import load_with
    from cananalyze.core.errors import UsageError

    if args.log == "-":
        raise UsageError("--against: the log is read twice, so it must be a file, not stdin")
    opts = options(args, checks=True, nodes=None, services=None, t_from=None, t_to=None)
    a = load_with(args.log, opts)
    c = diff.against(a, args.against, opts, args.tolerance, args.tolerance_ms, args.ref_node)
    if c.problems is not None:
        report_problems(c.problems)
    return c
