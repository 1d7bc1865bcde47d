"""`cananalyze diff A B`: two runs compared per node; exit 0 same, 1 different, 2 error."""

from __future__ import annotations

import argparse
import json
import sys

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, options, report_problems


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "diff",
        help="compare two runs per node: configuration, identity, PDOs, timing, states, EMCY, "
        "findings (exit 1 when they differ)",
        description="Compare two logs of a network, node by node, at the level an engineer "
        "judges a run: configuration objects, identity, PDO layout and rates, heartbeat and "
        "SYNC timing (within a tolerance), NMT and drive state sequences, EMCY codes and "
        "findings by rule. B may be a DCF (or an XDC): then only the configuration is compared. Exit 0 "
        "when the same within tolerances, 1 when different, 2 on bad input.",
    )
    options_.add(p, *options_.INPUT, "reference", "rules", extra_names=DBC)
    options_.add(p, "tolerance", "tolerance_ms", "diff_json", "reference_node", "quiet")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.api import diff
    from cananalyze.api.capture import load_with
    from cananalyze.core.text import printable

    opts = options(args, checks=True)
    a = load_with(args.log, opts)
    report_problems(a.problems)
    c = diff.against(a, args.reference, opts, args.tolerance, args.tolerance_ms, args.ref_node)
    if c.problems is not None:
        report_problems(c.problems)
    found, note = c.differences, c.note
    if args.diff_json:
        doc = {
            "a": str(args.log),
            "b": str(args.reference),
            "same": not found,
            "differences": [d.as_dict() for d in found],
        }
        text = json.dumps(doc, indent=1, default=str) + "\n"
        if args.diff_json == "-":
            sys.stdout.write(text)
        else:
            with open(args.diff_json, "w", encoding="utf-8") as f:
                f.write(text)
    if args.diff_json != "-":
        _print(found, args, note, printable)
    return 1 if found else 0


def _print(found: list, args, note: str, printable) -> None:
    out = sys.stdout
    out.write(f"A: {printable(str(args.log))}\nB: {printable(str(args.reference))}\n")
    node = None
    for d in found:
        if d.node != node:
            node = d.node
            out.write(f"{'network' if node == 'network' else 'node ' + node}:\n")
        out.write(f"  {printable(d.text)}\n")
    if note:
        out.write(f"{note}\n")
    out.write(f"{len(found)} difference(s)\n" if found else "same within tolerances\n")
