"""`cananalyze simulate`: emulate the seed devices (or a network file's nodes) and a master.

With --to FILE the scenario runs on a simulated clock and is written as a log
(suffix picks candump/ASC/BLF); with -i/-c it runs in real time on a python-can bus.
"""

from __future__ import annotations

import argparse

from cananalyze.core.errors import InputError, UsageError


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="emulate CANopen devices and a master: write a log or drive a bus",
        description=__doc__.splitlines()[0],
    )
    p.add_argument(
        "--network",
        metavar="FILE",
        help="network file (docs/network-file.md; default: one of each seed device)",
    )
    p.add_argument(
        "-i",
        "--interface",
        help="python-can interface for real-time mode (e.g. socketcan, virtual)",
    )
    p.add_argument("-c", "--channel", help="python-can channel for real-time mode (e.g. can0)")
    p.add_argument(
        "--to",
        metavar="FILE",
        help="write the traffic to a log (.log candump, .asc, .blf) on a simulated clock",
    )
    p.add_argument(
        "--duration", type=float, default=10.0, metavar="S", help="seconds to simulate (default 10)"
    )
    p.add_argument(
        "--seed", type=int, default=0, help="random seed: same seed, same log (default 0)"
    )
    p.add_argument(
        "--scenario",
        default="steady",
        help="what the master does: steady, commissioning or faults (default steady)",
    )
    p.add_argument(
        "--bitrate",
        type=int,
        default=None,
        help="bus bit rate for frame timing (default: network file or 500000)",
    )
    p.add_argument(
        "--no-master",
        action="store_true",
        help="real-time mode: emulate only the devices, another tool is the master",
    )
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
        bus = can.Bus(interface=args.interface, channel=args.channel)
    except (can.CanError, ValueError, ImportError, OSError) as exc:
        raise InputError(f"cannot open {args.interface} channel {args.channel}: {exc}") from None
    try:
        sim.run_realtime(bus, args.duration)
    finally:
        bus.shutdown()
    return 0
