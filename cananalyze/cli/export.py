"""`cananalyze export LOG --mcap F --rrd F --parquet DIR --csv DIR --dbc F`: timelines,
tables, and the network's PDOs as a DBC."""

from __future__ import annotations

import argparse
import sys
import time

from cananalyze.cli.common import add_filter_options, add_input_options, options, report_problems
from cananalyze.core.errors import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="write a log as MCAP (Foxglove), .rrd (Rerun), Parquet or CSV",
        description="Decode a log once and write it in one or more timeline/table formats. "
        "The CANopen rules run as for `check`: their findings are in every output.",
    )
    add_input_options(p, dbc_flag="--dbc-in")
    p.add_argument(
        "--mcap", metavar="FILE", help="MCAP file for Foxglove (PDO signal topics, events)"
    )
    p.add_argument(
        "--mcap-compression",
        choices=["zstd", "lz4", "none"],
        default="zstd",
        help="MCAP chunk compression (default zstd)",
    )
    p.add_argument("--rrd", metavar="FILE", help="Rerun recording (.rrd)")
    p.add_argument(
        "--parquet", metavar="DIR", help="directory for frames/signals/sdo/events/... .parquet"
    )
    p.add_argument("--csv", metavar="DIR", help="directory for the same tables as CSV")
    p.add_argument(
        "--dbc",
        metavar="FILE",
        help="DBC file (written with cantools) of the network's PDOs as configured at the "
        "end of the log, SDO remaps included (to read a DBC, use --dbc-in)",
    )
    p.add_argument(
        "--parquet-compression",
        choices=["snappy", "zstd", "lz4", "none"],
        default="snappy",
        help="Parquet page compression (default snappy, as pandas writes; zstd files are "
        "40 %% smaller but cost 1/3 more time at 10M frames)",
    )
    p.add_argument("--rules", metavar="FILE", help="rules file: its assertions join the findings")
    p.add_argument(
        "--no-check",
        action="store_true",
        help="skip the CANopen rules (no findings; a little faster)",
    )
    p.add_argument("--bitrate", type=int, metavar="BIT/S", help="bus bitrate: bus load in percent")
    add_filter_options(p)
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary line")
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
    if not args.quiet:
        dests = ", ".join(f"{kind} {getattr(args, kind)}" for kind in outputs)
        print(
            f"exported {state.frames:,} frames: decode and {dests} {time.perf_counter() - t0:.2f} s",
            file=sys.stderr,
        )
    return 0
