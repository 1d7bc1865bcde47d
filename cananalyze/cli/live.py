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

from ..errors import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live",
        help="sniff a live bus: dashboard or decoded lines, optional recording",
        description="Decode a live CAN bus through python-can. Without -i/-c python-can's own "
        "configuration (~/.canrc, CAN_INTERFACE/CAN_CHANNEL/CAN_BITRATE) applies.",
    )
    p.add_argument(
        "-i", "--interface", help="python-can interface (socketcan, pcan, slcan, virtual, ...)"
    )
    p.add_argument("-c", "--channel", help="channel (can0, PCAN_USBBUS1, /dev/ttyACM0, ...)")
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
        "--plain", action="store_true", help="decode-style lines instead of the dashboard"
    )
    p.add_argument("--no-color", action="store_true", help="no ANSI colours in --plain output")
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


def run(args: argparse.Namespace) -> int:
    from ..checks.build import attach_checker
    from ..io.live import HwFilter, LiveSource, open_bus
    from ..io.record import FrameRecorder
    from ..outputs.dashboard import LiveView
    from .pipeline import build_decoder

    try:
        filters = [HwFilter.parse(f) for f in args.filter]
    except ValueError as exc:
        raise UsageError(f"--filter: {exc}") from None
    if args.duration is not None and args.duration <= 0:
        raise UsageError("--duration must be positive")
    if (args.junit or args.json) and not args.check:
        raise UsageError("--junit and --json report a check: give --check RULES too")
    options = _bus_options(args.bus_option)
    # Frames are time-stamped on the reader thread as they are read; with the default 5 ms
    # GIL switch interval a decode on the main thread can hold them back that long, which
    # shows up as SDO latency and heartbeat jitter that the bus never had.
    sys.setswitchinterval(0.0005)
    checker = None
    if args.check:
        from ..checks.build import build_checker

        checker = build_checker(args.check)
    decoder = build_decoder(args)
    if checker is not None:
        attach_checker(decoder, checker)
    plain = args.plain or not sys.stdout.isatty()
    recorder = FrameRecorder(args.record) if args.record else None
    view = LiveView(
        bitrate=args.bitrate, model=getattr(decoder, "network", None), checking=checker is not None
    )
    timeline = None
    source = None
    try:
        if args.rrd or args.rerun:
            from ..outputs.rerun.live import RerunLive

            timeline = RerunLive(
                rrd=args.rrd,
                spawn=args.rerun,
                bitrate=args.bitrate,
                name=f"live {args.interface or ''} {args.channel or ''}".strip(),
                network=args.network or "",
            )
        bus = open_bus(args.interface, args.channel, args.bitrate, filters, **options)
        source = LiveSource(bus, channel_name=_label(args.channel, bus))
        _serve(args, source, decoder, view, recorder, timeline, plain)
    finally:
        if source is not None:
            source.close()
        if recorder is not None:
            recorder.close()
            print(f"recorded {recorder.frames} frames to {args.record}", file=sys.stderr)
        if timeline is not None:
            timeline.close()
            if args.rrd:
                print(f"wrote {args.rrd}", file=sys.stderr)
        if source is not None:
            sys.stdout.flush()
            print("\n".join(view.summary.lines(args.bitrate)))
            sys.stdout.flush()
    if checker is not None:
        from .check import check_result

        return check_result(checker, args.junit, args.json)
    return 0


def _label(channel: str | None, bus) -> str:
    """Channel name for frames whose Message carries none: short, like candump's can0.

    A serial device path becomes its file name (/dev/ttyACM0 -> ttyACM0, /dev/pts/3 -> pts3).
    """
    name = str(channel or getattr(bus, "channel_info", None) or "can0")
    if "/" in name:
        parent, _, base = name.rstrip("/").rpartition("/")
        name = parent.rpartition("/")[2] + base if base.isdigit() else base
    return name[:12] or "can0"


def _serve(args, source, decoder, view, recorder, timeline, plain: bool) -> None:
    """The loop: decode each batch, record it, show it; until stopped, timed out or failed."""
    deadline = time.monotonic() + args.duration if args.duration else None

    def stop(signum, frame):
        source.stop()
        signal.signal(
            signum, signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL
        )

    old = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    if recorder is not None:
        view.status = f"recording to {args.record}"
    try:
        if plain:
            from ..outputs.text.writer import TextWriter

            writer = TextWriter(sys.stdout, color=sys.stdout.isatty() and not args.no_color)
            for fb in source.batches():
                batch = decoder.decode(fb)  # empty batches too: they carry time forward
                view.add(batch)
                if timeline is not None:
                    timeline.add(batch)
                if len(fb):
                    if recorder is not None:
                        recorder.write(fb)
                    writer.write(batch)
                    sys.stdout.flush()
                if deadline is not None and time.monotonic() >= deadline:
                    source.stop()
            tail = decoder.finish()
            view.add(tail)
            if timeline is not None:
                timeline.add(tail)
            writer.write(tail)
            sys.stdout.flush()
        else:
            from rich.console import Console
            from rich.live import Live

            console = Console()
            shown = 0.0
            with Live(
                view.render(height=console.height),
                console=console,
                auto_refresh=False,
                screen=False,
                transient=False,
                redirect_stderr=False,
            ) as live:
                for fb in source.batches():
                    batch = decoder.decode(fb)
                    view.add(batch)
                    if timeline is not None:
                        timeline.add(batch)
                    if recorder is not None:
                        recorder.write(fb)
                    now = time.monotonic()
                    if now - shown >= 0.25 or source.stopping:
                        live.update(view.render(height=console.height), refresh=True)
                        shown = now
                    if deadline is not None and now >= deadline:
                        source.stop()
                tail = decoder.finish()
                view.add(tail)
                if timeline is not None:
                    timeline.add(tail)
                live.update(view.render(height=console.height), refresh=True)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
