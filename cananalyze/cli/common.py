"""Options shared by the commands that read a log (decode, check, export, live)."""

from __future__ import annotations

import argparse
import sys

from ..errors import ProblemLog


def add_input_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "log", help="log file (candump, ASC, BLF, TRC, CSV; .gz too), or - for stdin"
    )
    parser.add_argument(
        "--strict",
        action="store_true",
        help="stop at the first unreadable line or record (exit 2) instead of skipping it",
    )
    parser.add_argument(
        "--input-format", metavar="NAME", help="force the log format instead of detecting it"
    )
    parser.add_argument(
        "--sdo-timeout",
        type=float,
        default=1.0,
        metavar="S",
        help="an SDO request unanswered this long is a timeout (default 1 s)",
    )
    parser.add_argument(
        "--device",
        action="append",
        default=[],
        metavar="NODE=NAME",
        help="node NODE is this built-in device (dat7130, dat7014, i7231d, mcb560); repeatable",
    )
    parser.add_argument(
        "--eds",
        action="append",
        default=[],
        metavar="NODE=FILE",
        help="node NODE is described by this EDS/DCF file; repeatable",
    )
    parser.add_argument(
        "--network",
        metavar="FILE",
        help="network file (TOML/YAML): nodes, profiles, PDO/heartbeat overrides, SDO channels",
    )


def report_problems(problems: ProblemLog, stream=None) -> None:
    """Warnings for skipped input, with file and line, and the total at the end."""
    stream = stream or sys.stderr  # looked up per call: a default would keep a replaced stderr
    for p in problems.shown:
        print(f"warning: {p}", file=stream)
    if problems.count > len(problems.shown):
        print(f"warning: ... and {problems.count - len(problems.shown)} more", file=stream)
    if problems.count:
        print(f"warning: {problems.count} unreadable lines/records skipped", file=stream)
