"""Options shared by the commands that read a log (decode, check, export, live), and the
one place that turns them into the pipeline's `Options`."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from cananalyze.core.errors import ProblemLog, UsageError

if TYPE_CHECKING:
    from cananalyze.pipeline import Options


def add_input_options(parser: argparse.ArgumentParser, dbc_flag: str = "--dbc") -> None:
    parser.add_argument(
        "log", help="log file (candump, ASC, BLF, TRC, CSV, pcap/pcapng; .gz too), or - for stdin"
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
    add_device_options(parser, dbc_flag)


def report_problems(problems: ProblemLog, stream=None) -> None:
    """Warnings for skipped input, with file and line, and the total at the end."""
    stream = stream or sys.stderr  # looked up per call: a default would keep a replaced stderr
    for p in problems.shown:
        print(f"warning: {p}", file=stream)
    if problems.count > len(problems.shown):
        print(f"warning: ... and {problems.count - len(problems.shown)} more", file=stream)
    if problems.count:
        print(f"warning: {problems.count} unreadable lines/records skipped", file=stream)


def add_device_options(parser: argparse.ArgumentParser, dbc_flag: str = "--dbc") -> None:
    """--device, --eds, --network, --dbc: what the user knows about the nodes and the bus.

    `dbc_flag`: export's `--dbc` names the DBC it writes, so it reads one as `--dbc-in`
    (every command takes `--dbc-in`, so scripts can pass one name to all)."""
    parser.add_argument(
        "--device",
        action="append",
        default=[],
        metavar="NODE=NAME",
        help="node NODE is this built-in device (dat7130, dat7014, i7231d, mcb560) or a CiA profile's defaults (cia402 drive, cia401 I/O); repeatable",
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
    flags = [dbc_flag] if dbc_flag == "--dbc-in" else [dbc_flag, "--dbc-in"]
    parser.add_argument(
        *flags,
        dest="dbc_in",
        action="append",
        default=[],
        metavar="FILE",
        help="DBC file (read with cantools): its messages decoded as signals, its layouts, "
        "scaling, units and value tables winning over the profile's PDOs; repeatable",
    )


def add_filter_options(parser: argparse.ArgumentParser) -> None:
    """--node, --service, --from, --to: what the outputs show (decoding sees everything)."""
    parser.add_argument("--node", metavar="N[,N]", help="only frames and records of these node-IDs")
    parser.add_argument(
        "--service",
        metavar="S[,S]",
        help="only these services (nmt, sync, time, emcy, tpdo, rpdo, pdo, sdo, heartbeat, ...)",
    )
    parser.add_argument(
        "--from",
        dest="t_from",
        type=float,
        metavar="S",
        help="start, seconds after the first frame",
    )
    parser.add_argument(
        "--to", dest="t_to", type=float, metavar="S", help="end, seconds after the first frame"
    )


def add_time_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--time",
        choices=["rel", "abs"],
        default="rel",
        help="times in text output: seconds from the first frame (rel, default) or as logged "
        "(abs, like candump -ta)",
    )


def _node_assignments(items: list[str] | None, option: str) -> dict[int, str]:
    out: dict[int, str] = {}
    for item in items or []:
        node, sep, value = str(item).partition("=")
        try:
            node_id = int(node, 0)
        except ValueError:
            node_id = -1
        if not sep or not value or not 1 <= node_id <= 127:
            raise UsageError(f"{option} takes NODE=VALUE with NODE 1..127 (got {item!r})")
        out[node_id] = value
    return out


def _node_set(text: str | None) -> frozenset[int] | None:
    if not text:
        return None
    try:
        return frozenset(int(x, 0) for x in text.split(",") if x.strip())
    except ValueError:
        raise UsageError(f"--node takes node-IDs like 5 or 5,6 (got {text!r})") from None


def _service_set(text: str | None) -> frozenset[int] | None:
    if not text:
        return None
    from cananalyze.protocol.services import parse_services

    try:
        return frozenset(int(s) for s in parse_services(text))
    except ValueError as exc:
        raise UsageError(f"--service: {exc}") from None


def options(args: argparse.Namespace, **overrides) -> Options:
    """The pipeline's Options from parsed arguments (only the ones the command has)."""
    from cananalyze.pipeline import Options

    get = lambda name, default=None: getattr(args, name, default)  # noqa: E731
    values = dict(
        network=get("network"),
        devices=_node_assignments(get("device"), "--device"),
        eds=_node_assignments(get("eds"), "--eds"),
        rules=get("rules"),
        sdo_timeout=get("sdo_timeout", 1.0),
        strict=bool(get("strict", False)),
        input_format=get("input_format"),
        bitrate=get("bitrate"),
        nodes=_node_set(get("node")),
        services=_service_set(get("service")),
        t_from=get("t_from"),
        t_to=get("t_to"),
        time=get("time") or "rel",
        dbc=tuple(get("dbc_in") or ()),
    )
    values.update(overrides)
    return Options(**values)


def run_with_progress(source, decoder, sinks: list, opts: Options, quiet: bool = False):
    """`pipeline.run` with a progress bar on a terminal (unless quiet), and a warning when
    the filters matched nothing."""
    from cananalyze.pipeline import run, unmatched_filter

    sinks = list(sinks)
    if not quiet and sys.stderr.isatty():
        from cananalyze.outputs.progress import ProgressSink

        sinks.append(ProgressSink(sys.stderr))
    state = run(source, decoder, sinks, opts)
    warning = unmatched_filter(state)
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    return state
