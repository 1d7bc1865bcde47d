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


class Timelines:
    """decode's timeline outputs, fed each decoded batch.

    The MCAP file is written batch by batch (`StreamMcap`: memory flat in log
    length, the file appears only when complete); a Rerun viewer is shown the
    whole log at the end, so only then is the log kept (a `Collector`).
    """

    def __init__(self, args: argparse.Namespace) -> None:
        if args.rerun and args.connect:
            raise UsageError(
                "--rerun spawns a viewer, --connect uses a running one: give one of them"
            )
        self.args = args
        self.mcap = None
        self.collector = None
        if args.mcap:
            from ..capture import given_profiles
            from ..outputs.mcap_stream import StreamMcap

            network = getattr(args, "network", None) or ""
            self.mcap = StreamMcap(
                args.mcap, source=str(args.log), network=network, profiles=given_profiles(args)
            )
        if args.rerun or args.connect:
            from ..capture import Collector

            self.collector = Collector(str(args.log))

    def __bool__(self) -> bool:
        return self.mcap is not None or self.collector is not None

    def __enter__(self) -> Timelines:
        return self

    def __exit__(self, typ, exc, tb) -> None:
        if exc is not None and self.mcap is not None:
            self.mcap.abort(typ, exc, tb)

    def add(self, batch) -> None:
        if self.mcap is not None:
            self.mcap.add(batch)
        if self.collector is not None:
            self.collector.add(batch)

    def finish(self, problems) -> None:
        """Complete the MCAP file, then show the log in Rerun."""
        if self.mcap is not None:
            self.mcap.close(problems.count)
        if self.collector is not None:
            from ..outputs.rerun_out import show

            network = getattr(self.args, "network", None) or ""
            cap = self.collector.capture(problems, network)
            show(cap, connect=self.args.connect, bitrate=getattr(self.args, "bitrate", None))
