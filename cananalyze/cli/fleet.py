"""`cananalyze fleet INPUT... --out DATASET`: many logs decoded on Dask into one Parquet dataset."""

from __future__ import annotations

import argparse
import sys

from cananalyze.cli.common import add_device_options, options
from cananalyze.core.errors import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fleet",
        help="decode many logs in parallel (Dask) into one partitioned Parquet dataset",
        description="Decode every log the inputs name (files, folders searched recursively, "
        "globs; any format, mixed) as `export --parquet` does, one Dask task per log, into "
        "DATASET/<table>/date=YYYY-MM-DD/part-<hash>.parquet. Logs already in the dataset "
        "(same content, same cananalyze) are skipped. A network.toml beside logs is used for "
        "them instead of --network. Exit 0 when every log decoded and no rule was violated, "
        "1 when a log failed or had violations, 2 on usage errors.",
    )
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="log file, folder or glob")
    p.add_argument("--out", required=True, metavar="DATASET", help="the dataset folder")
    add_device_options(p)
    p.add_argument("--rules", metavar="FILE", help="rules file: its assertions join the findings")
    p.add_argument(
        "--sdo-timeout",
        type=float,
        default=1.0,
        metavar="S",
        help="an SDO request unanswered this long is a timeout (default 1 s)",
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="a log with an unreadable line or record fails (instead of skipping the line)",
    )
    p.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local worker processes (default: the number of cores)",
    )
    p.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="use this running Dask scheduler instead of a local cluster "
        "(its workers must see the same paths)",
    )
    p.add_argument("--force", action="store_true", help="decode logs already in the dataset again")
    p.add_argument("--junit", metavar="FILE", help="JUnit XML report, one testsuite per log")
    p.add_argument(
        "--parquet-compression",
        choices=["snappy", "zstd", "lz4", "none"],
        default="snappy",
        help="Parquet page compression (default snappy)",
    )
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.fleet.orchestrate import run_fleet, summary_lines

    if args.workers is not None and args.scheduler:
        raise UsageError("fleet: --workers sizes a local cluster; leave it out with --scheduler")
    opts = options(args, checks=True)
    if opts.rules:
        from cananalyze.pipeline import build_checker

        build_checker(opts)  # a bad rules file fails here, not once per log
    if opts.network:
        from cananalyze.pipeline import network_spec

        network_spec(opts)  # as a bad --network, --device or --eds
    result = run_fleet(
        args.inputs,
        args.out,
        opts,
        workers=args.workers,
        scheduler=args.scheduler,
        force=args.force,
        junit=args.junit,
        compression=args.parquet_compression,
        stream=None if args.quiet else sys.stderr,
    )
    lines = summary_lines(result)
    if args.quiet:
        lines = lines[1:]  # the failures and violations are the verdict: always listed
    for line in lines:
        print(line, file=sys.stderr)
    return result.exit_code
