"""`cananalyze fleet INPUT... --out DATASET`: many logs decoded on Dask into one Parquet dataset."""

from __future__ import annotations

import argparse
import sys

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, options
from cananalyze.core.errors import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fleet",
        help="decode many logs in parallel (Dask) into one partitioned Parquet dataset",
        description="Decode every log the inputs name (files, folders searched recursively, "
        "globs; local or fsspec URLs such as s3://bucket/logs; any format, mixed) as `export --parquet` does, one Dask task per log, into "
        "DATASET/<table>/date=YYYY-MM-DD/part-<hash>.parquet. Logs already in the dataset "
        "(same content, same cananalyze) are skipped. A network.toml beside logs is used for "
        "them instead of --network. Exit 0 when every log decoded and no rule was violated, "
        "1 when a log failed or had violations, 2 on usage errors.",
    )
    options_.add(p, "inputs", "out", "device", "eds", "network", "dbc_in", extra_names=DBC)
    options_.add(p, "rules", "sdo_timeout", "strict", "workers", "scheduler", "force", "junit")
    options_.add(p, "parquet_compression", "storage_options", "task_timeout")
    options_.add(p, "batch", "compact", "target_size", "quiet")
    p.set_defaults(func=run)
    c = sub.add_parser(
        "fleet-compact",
        help="(cananalyze fleet compact DATASET) rewrite a dataset's small parts into large files",
        description="Rewrite each table's date partitions of a fleet dataset: the parts "
        "smaller than --target-size become files near that size, rows in time order, each "
        "row keeping its log's lineage. Readers see whole files throughout; a rerun of "
        "`fleet` still skips the logs in it. DATASET may be a URL (s3://bucket/ds).",
    )
    options_.add(c, "dataset", "target_size", "parquet_compression", "storage_options", "quiet")
    c.set_defaults(func=run_compact)


def run(args: argparse.Namespace) -> int:
    from cananalyze.core.storage import parse_options
    from cananalyze.fleet.orchestrate import run_fleet, summary_lines

    if args.workers is not None and args.scheduler:
        raise UsageError("fleet: --workers sizes a local cluster; leave it out with --scheduler")
    opts = options(args, checks=True)
    checker = None
    if opts.rules:
        from cananalyze.pipeline import build_checker

        checker = build_checker(opts)  # a bad rules file fails here, not once per log
    if opts.network:
        from cananalyze.pipeline import network_spec

        network_spec(opts, checker)  # as a bad --network, --device or --eds
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
        storage_options=parse_options(args.storage_options) or None,
        task_timeout=args.task_timeout,
        compact_to=args.target_size if args.compact else None,
        batch=args.batch,
    )
    lines = summary_lines(result)
    if args.quiet:
        lines = lines[1:]  # the failures and violations are the verdict: always listed
    for line in lines:
        print(line, file=sys.stderr)
    return result.exit_code


def run_compact(args: argparse.Namespace) -> int:
    from cananalyze.core.storage import parse_options
    from cananalyze.fleet.compact import compact, median

    where = parse_options(args.storage_options) or None
    out = compact(args.dataset, args.target_size, args.parquet_compression, options=where)
    if not args.quiet:
        before, after = out.sizes_before, out.sizes_after
        print(
            f"compact: {len(before)} files (median {median(before) / 1024:,.1f} KB) -> "
            f"{len(after)} files (median {median(after) / 1024:,.1f} KB), {out.merged} written"
            + (f", {out.reconciled} rewritten without replaced logs" if out.reconciled else ""),
            file=sys.stderr,
        )
    return 0
