"""`cananalyze export LOG --mcap F --rrd F --parquet DIR --csv DIR --dbc F`: timelines,
tables, and the network's PDOs as a DBC."""

from __future__ import annotations

import argparse
import sys
import time

from cananalyze.cli import options as options_
from cananalyze.cli.common import options, report_problems
from cananalyze.core.errors import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="write a log as MCAP (Foxglove), .rrd (Rerun), Parquet or CSV",
        description="Decode a log once and write it in one or more timeline/table formats. "
        "The CANopen rules run as for `check`: their findings are in every output.",
    )
    options_.add(p, *options_.INPUT, "mcap", "mcap_compression", "rrd", "parquet", "csv")
    options_.add(p, "dbc_out", "parquet_compression", "rules", "no_check", "bitrate")
    options_.add(p, *options_.FILTERS, "quiet")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    outputs = [o for o in ("mcap", "rrd", "parquet", "csv", "dbc") if getattr(args, o)]
    if not outputs:
        raise UsageError(
            "export: give at least one of --mcap FILE, --rrd FILE, --parquet DIR, --csv DIR, "
            "--dbc FILE"
        )
    if args.no_check and args.rules:
        raise UsageError("export: --rules needs the checks; leave out --no-check")
    from cananalyze.cli.common import run_with_progress
    from cananalyze.pipeline import build_checker, build_decoder, open_source

    t0 = time.perf_counter()
    opts = options(args, checks=not args.no_check)
    # a bad rules file fails first; the sinks take the findings from the batches
    checker = build_checker(opts, keep_findings=False) if opts.checking else None
    source = open_source(args.log, opts)
    decoder = build_decoder(opts, checker)
    sinks = []
    for kind in ("parquet", "csv"):
        if getattr(args, kind):
            from cananalyze.outputs.tables.stream import TableSink

            sinks.append(TableSink(getattr(args, kind), kind, args.parquet_compression))
    if args.mcap:
        from cananalyze.outputs.mcap.sink import McapSink

        sinks.append(McapSink(args.mcap, args.mcap_compression))
    if args.rrd:
        from cananalyze.outputs.rerun.sink import RerunSink

        sinks.append(RerunSink(args.rrd, bitrate=args.bitrate))
    if args.dbc:
        from cananalyze.outputs.dbc import DbcSink

        sinks.append(DbcSink(args.dbc))
    state = run_with_progress(source, decoder, sinks, opts, quiet=args.quiet)
    report_problems(source.problems)
    empty = [s for s in sinks if getattr(s, "messages", None) == 0]  # a DBC of no message
    for _ in empty:
        print(
            f"warning: {args.dbc}: DBC with no message: no PDO of a known device in this log "
            "(name the devices with --device, --eds or --network)",
            file=sys.stderr,
        )
    if not args.quiet:
        dests = ", ".join(f"{kind} {getattr(args, kind)}" for kind in outputs)
        print(
            f"exported {state.frames:,} frames: decode and {dests} {time.perf_counter() - t0:.2f} s",
            file=sys.stderr,
        )
    return 1 if empty and getattr(args, "strict", False) else 0
