"""`decode --mcap FILE / --rerun / --connect ADDR`: timelines alongside the decoded text."""

from __future__ import annotations

import argparse

from ..errors import UsageError


def add_timeline_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mcap", metavar="FILE", help="also write an MCAP file for Foxglove")
    p.add_argument(
        "--rerun", action="store_true", help="also show the log in a spawned Rerun viewer"
    )
    p.add_argument(
        "--connect",
        metavar="ADDR",
        help="also stream to a running Rerun viewer (host:port or rerun+http:// URL)",
    )


def timeline_collector(args: argparse.Namespace):
    """A Collector when a timeline output is asked for, else None (no memory kept)."""
    if not (args.mcap or args.rerun or args.connect):
        return None
    if args.rerun and args.connect:
        raise UsageError("--rerun spawns a viewer, --connect uses a running one: give one of them")
    from ..capture import Collector
    from ..outputs.atomic import check_writable

    if args.mcap:
        check_writable(args.mcap)
    return Collector(str(args.log))


def write_timelines(args: argparse.Namespace, cap) -> None:
    if args.mcap:
        from ..outputs.mcap_out import write_mcap

        write_mcap(cap, args.mcap)
    if args.rerun or args.connect:
        from ..outputs.rerun_out import show

        show(cap, connect=args.connect, bitrate=getattr(args, "bitrate", None))
