"""`cananalyze boot LOG`: why each node did (not) start: its CiA 302-2 boot, step by step."""

from __future__ import annotations

import argparse
import sys

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, options, report_problems


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "boot",
        help="each node's boot story: identity, configuration, error control, NMT start, "
        "and where it stopped (CiA 302-2 error status)",
        description="Reconstruct each node's boot from the log, as a CiA 302-2 master runs "
        "it: boot-up, identity read (against the device declared with --device, --eds or the "
        "network file), configuration written, program download, error control, NMT start; "
        "the step where it stopped and the CiA 302-2 boot error status (A-O) it matches.",
    )
    options_.add(p, *options_.INPUT, "format", "quiet", extra_names=DBC)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.cli.common import run_with_progress
    from cananalyze.outputs.boot import BootSink
    from cananalyze.pipeline import build_checker, build_decoder, open_source

    opts = options(args, checks=True)
    checker = build_checker(opts)  # the configuration in force (heartbeat times)
    source = open_source(args.log, opts)
    decoder = build_decoder(opts, checker)
    try:
        run_with_progress(
            source, decoder, [BootSink(sys.stdout, args.format)], opts, quiet=args.quiet
        )
    finally:
        report_problems(source.problems)
    return 0
