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

from cananalyze.cli.common import add_time_option
from cananalyze.core.errors import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live",
        help="sniff a live bus: dashboard or decoded lines, optional recording",
        description="Decode a live CAN bus through python-can. Without -i/-c python-can's own "
        "configuration (~/.canrc, CAN_INTERFACE/CAN_CHANNEL/CAN_BITRATE) applies.",
    )
    p.add_argument(
        "-i",
        "--interface",
        action="append",
        help="python-can interface (socketcan, pcan, slcan, virtual, ...); repeat with -c "
        "for several buses",
    )
    p.add_argument(
        "-c",
        "--channel",
        action="append",
        help="channel (can0, PCAN_USBBUS1, /dev/ttyACM0, ...); several buses: can0,can1 or "
        "repeated -i/-c pairs",
    )
    p.add_argument(
        "-b", "--bitrate", type=int, metavar="BIT/S", help="bus bitrate (also for the bus load)"
    )
    p.add_argument(
        "--filter",
        action="append",
        default=[],
        metavar="ID:MASK",
        help="hardware acceptance filter, hex (e.g. 580:780 = SDO responses); repeatable",
    )
    p.add_argument(
        "--bus-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra python-can interface argument (e.g. tty_baudrate=921600); repeatable",
    )
    p.add_argument(
        "--network",
        metavar="FILE",
        help="network file (TOML/YAML): nodes, profiles, PDO/heartbeat overrides, SDO channels",
    )
    p.add_argument(
        "--device",
        action="append",
        default=[],
        metavar="NODE=NAME",
        help="node NODE is this built-in device (dat7130, dat7014, i7231d, mcb560); repeatable",
    )
    p.add_argument(
        "--eds",
        action="append",
        default=[],
        metavar="NODE=FILE",
        help="EDS/DCF of a node; repeatable",
    )
    p.add_argument(
        "--dbc",
        "--dbc-in",
        dest="dbc_in",
        action="append",
        default=[],
        metavar="FILE",
        help="DBC file (cantools): its messages decoded as signals; repeatable",
    )
    p.add_argument(
        "--check",
        metavar="RULES",
        help="check the rules of this rules file live; exit 1 on violations, as `check` does",
    )
    p.add_argument("--junit", metavar="FILE", help="with --check: write a JUnit XML report at exit")
    p.add_argument(
        "--json", metavar="FILE", help="with --check: write the findings as JSON at exit"
    )
    p.add_argument(
        "--rerun", action="store_true", help="stream the timelines to a spawned Rerun viewer"
    )
    p.add_argument("--rrd", metavar="FILE", help="stream the timelines into a Rerun .rrd file")
    p.add_argument(
        "--foxglove",
        nargs="?",
        const="127.0.0.1:8765",
        metavar="HOST:PORT",
        help="serve the decode to Foxglove over WebSocket (default 127.0.0.1:8765; "
        "the topics of export --mcap)",
    )
    p.add_argument(
        "--plain", action="store_true", help="decode-style lines instead of the dashboard"
    )
    p.add_argument("--no-color", action="store_true", help="no ANSI colours in --plain output")
    add_time_option(p)
    p.add_argument(
        "--record", metavar="FILE", help="record the raw frames (.log candump, .asc, .blf, .mcap)"
    )
    p.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--sdo-timeout",
        type=float,
        default=1.0,
        metavar="S",
        help="an SDO request unanswered this long is a timeout (default 1 s)",
    )
    p.set_defaults(func=run, strict=False, input_format=None)


def _value(text: str):
    for conv in (int, float):
        try:
            return conv(text, 0) if conv is int else conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def _bus_options(items: list[str]) -> dict:
    out = {}
    for item in items:
        key, sep, val = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--bus-option {item!r}: expected KEY=VALUE")
        out[key.strip()] = _value(val.strip())
    return out


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
    bus_options = _bus_options(args.bus_option)
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
            lambda i=i, c=c: open_bus(i, c, args.bitrate, filters, **bus_options),
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
