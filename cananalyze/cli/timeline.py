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
    """decode's timeline outputs, fed each decoded batch as it is decoded.

    The MCAP file (`StreamMcap`) and the Rerun viewer (`StreamRrd`, spawned or
    connected) get every batch at once, so memory stays flat in log length; the
    MCAP file appears only when complete.
    """

    def __init__(self, args: argparse.Namespace) -> None:
        if args.rerun and args.connect:
            raise UsageError(
                "--rerun spawns a viewer, --connect uses a running one: give one of them"
            )
        from ..capture import given_profiles

        network = getattr(args, "network", None) or ""
        self.sinks: list = []
        self.mcap = None
        if args.mcap:
            from ..outputs.mcap.stream import StreamMcap

            self.mcap = StreamMcap(
                args.mcap, source=str(args.log), network=network, profiles=given_profiles(args)
            )
            self.sinks.append(self.mcap)
        self.viewer = None
        if args.rerun or args.connect:
            from ..outputs.rerun.stream import StreamRrd

            bitrate = getattr(args, "bitrate", None)
            self.viewer = StreamRrd(None, str(args.log), network, bitrate, connect=args.connect)
            self.sinks.append(self.viewer)

    def __bool__(self) -> bool:
        return bool(self.sinks)

    def __enter__(self) -> Timelines:
        return self

    def __exit__(self, typ, exc, tb) -> None:
        if exc is not None:
            for sink in self.sinks:
                sink.abort(typ, exc, tb)

    def add(self, batch) -> None:
        for sink in self.sinks:
            sink.add(batch)

    def finish(self, problems) -> None:
        """Complete the MCAP file; the viewer gets the bus load and its layout."""
        if self.mcap is not None:
            self.mcap.close(problems.count)
        if self.viewer is not None:
            self.viewer.close()
