"""`cananalyze live`: sniff a running bus through any python-can interface.

A dashboard on a terminal (nodes, PDO values, events), decode-style lines with
--plain or when stdout is not a terminal; optionally records the raw frames,
streams the timelines to rerun (--rrd/--rerun) and checks the rules of a rules
file as frames arrive (--check: same rules, report and exit codes as `check`).
Ctrl-C / SIGTERM end the session cleanly: recordings are finalised, the summary
and the check result printed. Interface failures end it the same way, then one
line and exit 2.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, bus_options, require_display_for_viewer
from cananalyze.core.errors import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live",
        help="sniff a live bus: dashboard or decoded lines, optional recording",
        description="Decode a live CAN bus through python-can. Without -i/-c python-can's own "
        "configuration (~/.canrc, CAN_INTERFACE/CAN_CHANNEL/CAN_BITRATE) applies.",
    )
    options_.add(p, "interface", "channel", "bitrate", "filter", "bus_option", "network", "device")
    options_.add(p, "eds", "dbc_in", "live_check", "junit", "json", extra_names=DBC)
    options_.add(p, "rerun", "rrd", "foxglove", "plain", "no_color", "time", "record", "duration")
    options_.add(p, "sdo_timeout")
    p.set_defaults(func=run, strict=False, input_format=None)


def buses(interfaces: list[str] | None, channels: list[str] | None) -> list[tuple]:
    """(interface, channel) per bus: `-c can0,can1` or repeated -c, with one -i for all
    or one -i per -c. No -c: one bus from python-can's configuration."""
    names = [c for item in channels or [] for c in item.split(",") if c.strip()]
    kinds = list(interfaces or [])
    if not names:
        if len(kinds) > 1:
            raise UsageError("several -i need one -c each")
        return [(kinds[0] if kinds else None, None)]
    if len(kinds) <= 1:
        return [(kinds[0] if kinds else None, c.strip()) for c in names]
    if len(kinds) != len(names):
        raise UsageError(f"{len(kinds)} -i for {len(names)} channels: give one -i, or one per -c")
    return [(i, c.strip()) for i, c in zip(kinds, names, strict=True)]


def run(args: argparse.Namespace) -> int:
    from cananalyze.cli.common import options
    from cananalyze.formats.live import HwFilter, LiveSource, open_bus
    from cananalyze.outputs.findings import FindingsSink
    from cananalyze.pipeline import build_checker, build_decoder
    from cananalyze.pipeline import run as run_pipeline

    try:
        filters = [HwFilter.parse(f) for f in args.filter]
    except ValueError as exc:
        raise UsageError(f"--filter: {exc}") from None
    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    if (args.junit or args.json) and not args.check:
        raise UsageError("--junit and --json report a check: give --check RULES too")
    if args.rerun:
        require_display_for_viewer(
            "write the timelines with --rrd FILE and open it where a display is"
        )
    extra = bus_options(args.bus_option)
    pairs = buses(args.interface, args.channel)
    where = " ".join(f"{i or ''} {c or ''}".strip() for i, c in pairs)
    # Frames are time-stamped on the reader thread as they are read; with the default 5 ms
    # GIL switch interval a decode on the main thread can hold them back that long, which
    # shows up as SDO latency and heartbeat jitter that the bus never had.
    sys.setswitchinterval(0.0005)
    opts = options(args, rules=args.check, checks=bool(args.check))
    checker = build_checker(opts) if args.check else None  # a bad rules file fails first
    decoder = build_decoder(opts, checker)
    plain = args.plain or not sys.stdout.isatty()
    sinks: list = []
    if args.record:
        from cananalyze.outputs.recording import RecordSink

        sinks.append(RecordSink(args.record))
    if args.rrd or args.rerun:
        from cananalyze.outputs.rerun.sink import RerunLiveSink

        sinks.append(
            RerunLiveSink(
                rrd=args.rrd,
                spawn=args.rerun,
                bitrate=args.bitrate,
                name=f"live {where}".strip(),
            )
        )
    if args.foxglove:
        from cananalyze.outputs.foxglove.sink import FoxgloveSink, parse_address

        sinks.append(FoxgloveSink(*parse_address(args.foxglove)))
    from cananalyze.outputs.dashboard import DashboardSink

    view = DashboardSink(
        bitrate=args.bitrate,
        checking=checker is not None,
        status=f"recording to {args.record}" if args.record else "",
        show=not plain,
        summary=sys.stdout,
    )
    if plain:
        from cananalyze.outputs.colour import use_colour
        from cananalyze.outputs.text.writer import TextWriter

        sinks.append(
            TextWriter(sys.stdout, color=use_colour(sys.stdout, args.no_color), flush=True)
        )
    sinks.append(view)  # the summary after the last line, before the check's verdict
    report = None
    if checker is not None:
        report = FindingsSink(sys.stdout, args.junit, args.json, no_color=args.no_color)
        sinks.append(report)
    # the bus opens once every output is open (see LiveSource); one reader per bus
    parts = [
        LiveSource(
            lambda i=i, c=c: open_bus(i, c, args.bitrate, filters, **extra),
            name_of=lambda bus, c=c: _label(c, bus),
        )
        for i, c in pairs
    ]
    if len(parts) == 1:
        source = parts[0]
    else:
        from cananalyze.formats.live_buses import LiveBuses

        source = LiveBuses(parts)
    deadline = time.monotonic() + args.duration if args.duration else None

    def stop(signum, frame):
        source.stop()
        signal.signal(
            signum, signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL
        )

    old = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        run_pipeline(
            source,
            decoder,
            sinks,
            opts,
            stop=(lambda: time.monotonic() >= deadline) if deadline is not None else None,
            tick=0.25,
        )
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        source.close()
        sys.stdout.flush()
    return report.exit_code if report is not None else 0


def _label(channel: str | None, bus) -> str:
    """Channel name for frames whose Message carries none: short, like candump's can0.

    A serial device path becomes its file name (/dev/ttyACM0 -> ttyACM0, /dev/pts/3 -> pts3).
    """
    name = str(channel or getattr(bus, "channel_info", None) or "can0")
    if "/" in name:
        parent, _, base = name.rstrip("/").rpartition("/")
        name = parent.rpartition("/")[2] + base if base.isdigit() else base
    return name[:12] or "can0"
