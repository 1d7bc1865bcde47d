"""`cananalyze od LOG`: each node's objects as the log's SDO transfers showed them, and DCFs."""

from __future__ import annotations

import argparse
import sys

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, options, report_problems


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "od",
        help="each node's object values as the log showed them; DCFs with --dcf",
        description="Rebuild each node's object dictionary from the log: every object a "
        "successful SDO upload or download showed, its last value in words, when and how it "
        "was set and the values it went through, per life of the node (boot-ups split it).",
    )
    options_.add(p, *options_.INPUT, "format", "dcf", "quiet", extra_names=DBC)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.cli.common import run_with_progress
    from cananalyze.outputs.od import OdSink
    from cananalyze.pipeline import build_decoder, open_source

    opts = options(args)
    source = open_source(args.log, opts)
    decoder = build_decoder(opts, None)
    try:
        run_with_progress(
            source, decoder, [OdSink(sys.stdout, args.format, args.dcf)], opts, quiet=args.quiet
        )
    finally:
        report_problems(source.problems)
    return 0
