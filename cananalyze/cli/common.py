"""The one place that turns parsed arguments into the pipeline's `Options`, and what every
command that reads a log does around the run (problems, progress). The flags are
declared in `options.py`."""

from __future__ import annotations

import argparse
import os
import sys
from typing import TYPE_CHECKING

from cananalyze.core.defaults import SDO_TIMEOUT
from cananalyze.core.errors import ProblemLog, UsageError

if TYPE_CHECKING:
    from cananalyze.pipeline import Options


def report_problems(problems: ProblemLog, stream=None) -> None:
    """Warnings for skipped input, with file and line, and the total at the end."""
    stream = stream or sys.stderr  # looked up per call: a default would keep a replaced stderr
    for note in problems.notes:
        print(f"note: {note}", file=stream)
    for p in problems.shown:
        print(f"warning: {p}", file=stream)
    if problems.count > len(problems.shown):
        print(f"warning: ... and {problems.count - len(problems.shown)} more", file=stream)
    if problems.count:
        print(f"warning: {problems.count} unreadable lines/records skipped", file=stream)


def _value(text: str) -> object:
    for conv in (int, float):
        try:
            return conv(text, 0) if conv is int else conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def bus_options(items: list[str]) -> dict[str, object]:
    """--bus-option KEY=VALUE items as python-can keywords (numbers and true/false typed),
    for `live` and `simulate` alike: udp_multicast's port, an adapter's tty_baudrate."""
    out = {}
    for item in items:
        key, sep, val = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--bus-option {item!r}: expected KEY=VALUE")
        out[key.strip()] = _value(val.strip())
    return out


def require_display_for_viewer(instead: str, environ: dict[str, str] | None = None) -> None:
    """Fail at once where `--rerun` cannot open its viewer: Linux with neither $DISPLAY nor
    $WAYLAND_DISPLAY. The spawned viewer would die unseen and the stream wait for it (a
    gRPC traceback after about 17 s); `instead` names what this command offers."""
    env = os.environ if environ is None else environ
    if sys.platform.startswith("linux") and not (env.get("DISPLAY") or env.get("WAYLAND_DISPLAY")):
        raise UsageError(
            f"--rerun: no display for a Rerun viewer ($DISPLAY and $WAYLAND_DISPLAY are unset); "
            f"{instead}"
        )


# every command that reads a DBC takes it as --dbc-in; those that write none also as --dbc
DBC = {"dbc_in": ("--dbc",)}


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
        sdo_timeout=get("sdo_timeout", SDO_TIMEOUT),
        fd=bool(get("fd", False)),
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
    the filters matched nothing. The bar's sink goes first: it is cleared before any other
    sink prints its results (outputs/progress.py)."""
    from cananalyze.pipeline import run, unmatched_filter

    sinks = list(sinks)
    if not quiet and sys.stderr.isatty():
        from cananalyze.outputs.progress import ProgressSink

        sinks.insert(0, ProgressSink(sys.stderr))
    state = run(source, decoder, sinks, opts)
    warning = unmatched_filter(state)
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    return state
