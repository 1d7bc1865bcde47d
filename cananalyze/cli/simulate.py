"""`cananalyze simulate`: emulate the seed devices (or a network file's nodes) and a master.

With --to FILE the scenario runs on a simulated clock and is written as a log
(suffix picks candump/ASC/BLF); with -i/-c it runs in real time on a python-can bus.
python-can's virtual bus reaches only its own process: for `live` in another terminal
use udp_multicast on a loopback-only group (docs/live.md, "Without hardware").
"""

from __future__ import annotations

import argparse

from cananalyze.cli import options as options_
from cananalyze.core.errors import InputError, UsageError


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="emulate CANopen devices and a master: write a log or drive a bus",
        description=__doc__.splitlines()[0],
    )
    options_.add(p, "network", "sim_interface", "sim_channel", "sim_to", "seed", "scenario")
    options_.add(p, "duration", "bitrate", "no_master", "bus_option", duration=10.0)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.sim.network import default_network, load_network
    from cananalyze.sim.scenarios import SCENARIOS
    from cananalyze.sim.session import build

    # checked here, not with argparse choices, so `--help` need not import the simulator
    if args.scenario not in SCENARIOS:
        raise UsageError(
            f"--scenario: unknown {args.scenario!r} (known: {', '.join(sorted(SCENARIOS))})"
        )
    if args.duration <= 0:
        raise UsageError("--duration must be positive")
    if bool(args.to) == bool(args.interface or args.channel):
        raise UsageError("give either --to FILE or -i INTERFACE -c CHANNEL")
    if args.interface and not args.channel:
        raise UsageError("-i needs -c CHANNEL")
    if args.to and args.bus_option:
        raise UsageError("--bus-option is for the bus of -i/-c, not for --to FILE")
    if args.network:
        net = load_network(args.network)
        profiles, bitrate, config = net.profiles, net.bitrate, net.config
    else:
        profiles, bitrate, config = default_network(), 500_000, {}
    bitrate = args.bitrate or bitrate
    if args.to:
        from cananalyze.formats.logfile import write_log

        if not args.to.lower().endswith((".log", ".asc", ".blf")):
            raise UsageError(f"{args.to}: --to writes .log (candump), .asc or .blf")
        sim, _, _ = build(profiles, args.scenario, args.duration, args.seed, bitrate, config=config)
        sim.run(args.duration)
        batch = sim.batch()
        try:
            write_log(batch, args.to)
        except OSError as exc:
            raise InputError(f"{args.to}: cannot write: {exc.strerror}") from None
        print(
            f"wrote {len(batch)} frames ({args.duration:g} s, scenario {args.scenario}) to {args.to}"
        )
        return 0
    import can

    from cananalyze.cli.common import bus_options

    extra = bus_options(args.bus_option)
    sim, _, _ = build(
        profiles,
        args.scenario,
        args.duration,
        args.seed,
        bitrate,
        master=not args.no_master,
        config=config,
    )
    try:
        bus = can.Bus(interface=args.interface, channel=args.channel, **extra)
    except (can.CanError, ValueError, ImportError, OSError) as exc:
        raise InputError(f"cannot open {args.interface} channel {args.channel}: {exc}") from None
    try:
        sim.run_realtime(bus, args.duration)
    finally:
        bus.shutdown()
    return 0
