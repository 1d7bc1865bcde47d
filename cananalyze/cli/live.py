"""`cananalyze live`: sniff a running bus through any python-can interface.

A dashboard on a terminal (nodes, PDO values, events), decode-style lines with
--plain or when stdout is not a terminal; optionally records the raw frames.
Ctrl-C / SIGTERM end the session cleanly: recordings are finalised, the summary
printed. Interface failures end it the same way, then one line and exit 2.
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
    p.add_argument("--network", metavar="FILE", help="network description (nodes, profiles)")
    p.add_argument(
        "--eds",
        action="append",
        default=[],
        metavar="NODE=FILE",
        help="EDS/DCF of a node; repeatable",
    )
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


def _eds_devices(items: list[str]) -> dict[int, str]:
    """Node -> device name from --eds NODE=FILE (the decoder gets the files too, via args)."""
    from ..network.profile import load_eds

    out = {}
    for item in items:
        node, sep, path = item.partition("=")
        try:
            n = int(node, 0)
        except ValueError:
            n = -1
        if not sep or not 1 <= n <= 127:
            raise UsageError(f"--eds {item!r}: expected NODE=FILE with NODE 1..127")
        out[n] = load_eds(path, n).name
    return out


def run(args: argparse.Namespace) -> int:
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
    options = _bus_options(args.bus_option)
    devices = _eds_devices(args.eds)
    decoder = build_decoder(args)
    plain = args.plain or not sys.stdout.isatty()
    recorder = FrameRecorder(args.record) if args.record else None
    view = LiveView(bitrate=args.bitrate, devices=devices)
    source = None
    try:
        bus = open_bus(args.interface, args.channel, args.bitrate, filters, **options)
        source = LiveSource(bus, channel_name=_label(args.channel, bus))
        _serve(args, source, decoder, view, recorder, plain)
    finally:
        if source is not None:
            source.close()
        if recorder is not None:
            recorder.close()
            print(f"recorded {recorder.frames} frames to {args.record}", file=sys.stderr)
        if source is not None:
            sys.stdout.flush()
            print("\n".join(view.summary.lines(args.bitrate)))
            sys.stdout.flush()
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


def _serve(args, source, decoder, view, recorder, plain: bool) -> None:
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
            from ..outputs.text import TextWriter

            writer = TextWriter(sys.stdout, color=sys.stdout.isatty() and not args.no_color)
            for fb in source.batches():
                batch = decoder.decode(fb)  # empty batches too: they carry time forward
                view.add(batch)
                if len(fb):
                    if recorder is not None:
                        recorder.write(fb)
                    writer.write(batch)
                    sys.stdout.flush()
                if deadline is not None and time.monotonic() >= deadline:
                    source.stop()
            tail = decoder.finish()
            view.add(tail)
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
                    view.add(decoder.decode(fb))
                    if recorder is not None:
                        recorder.write(fb)
                    now = time.monotonic()
                    if now - shown >= 0.25 or source.stopping:
                        live.update(view.render(height=console.height), refresh=True)
                        shown = now
                    if deadline is not None and now >= deadline:
                        source.stop()
                view.add(decoder.finish())
                live.update(view.render(height=console.height), refresh=True)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
