"""`cananalyze query DATASET "SQL"`: DuckDB over a fleet dataset's tables, as a table, CSV or JSON."""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
import sys

from cananalyze.cli import options as options_


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "query",
        help="SQL (DuckDB) over a fleet dataset: frames, signals, sdo, events, findings, nodes, logs",
        description="Run one SQL statement over a dataset written by `cananalyze fleet`. "
        "Each table is a view of its Parquet parts, with the partition column `date`.",
    )
    options_.add(p, "dataset", "sql", "storage_options")
    options_.add(p.add_mutually_exclusive_group(), "query_csv", "query_json")
    p.set_defaults(func=run)


def _plain(v):
    if isinstance(v, (dt.date, dt.datetime, dt.time)):
        return v.isoformat()
    if isinstance(v, bytes):
        return v.hex()
    if isinstance(v, float) and v != v:
        return None
    return v


def _cell(v) -> str:
    v = _plain(v)
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6f}".rstrip("0").rstrip(".") if abs(v) < 1e15 else repr(v)
    return str(v)


def print_table(names: list[str], rows: list[tuple], out=None) -> None:
    out = out or sys.stdout
    cells = [[_cell(v) for v in r] for r in rows]
    widths = [max([len(n)] + [len(c[i]) for c in cells]) for i, n in enumerate(names)]
    print("  ".join(n.ljust(w) for n, w in zip(names, widths, strict=True)).rstrip(), file=out)
    print("  ".join("-" * w for w in widths), file=out)
    for c in cells:
        print("  ".join(v.ljust(w) for v, w in zip(c, widths, strict=True)).rstrip(), file=out)
    print(f"({len(rows)} row{'s' if len(rows) != 1 else ''})", file=out)


def run(args: argparse.Namespace) -> int:
    from cananalyze.core.storage import parse_options
    from cananalyze.fleet.query import query

    names, rows = query(args.dataset, args.sql, parse_options(args.storage_options) or None)
    if args.csv:
        w = csv.writer(sys.stdout, lineterminator="\n")
        w.writerow(names)
        w.writerows([[_plain(v) for v in r] for r in rows])
    elif args.json:
        for r in rows:
            rec = {n: _plain(v) for n, v in zip(names, r, strict=True)}
            print(json.dumps(rec, default=str))
    else:
        print_table(names, rows)
    return 0
