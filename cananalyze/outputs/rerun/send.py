"""What a Rerun recording holds: PDO signals as plots, NMT states as lanes, events as a
text log, and its layout. Sent batch by batch by `stream.StreamRrd` (export, decode)
and `live.RerunLive` (live sessions).

Entities:
  /node/<N>/<pdo>/<signal>  Scalars (series named "signal [unit]")
  /node/<N>/nmt             StateChange lane (heartbeat, boot-up, guarding)
  /node/<N>/drive_state     StateChange lane of a CiA 402 drive (its statusword)
  /events                   TextLog with levels (SDO, EMCY, NMT, findings)
  /bus/load                 Scalars: bits/s, or percent with a bitrate
On a log of several buses each bus's entities carry its name in front, as the MCAP
topics do (`records.on_bus`): /can1/node/5/tpdo1/..., /can1/node/5/nmt, /can1/bus/load
(node 5 on can1 is another device than node 5 on can0, and two buses' loads summed
could read over 100 %); the event log stays one, each line naming its bus.
Everything is sent with `send_columns`, one call per series, never one `log` per
frame, so a million-frame log exports in about a second. Time is the `time`
timeline: a timestamp when the log has absolute (epoch) times, else a duration.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from cananalyze.core.records import on_bus, signal_path
from cananalyze.core.version import __version__
from cananalyze.outputs.capture import Capture

TIMELINE = "time"
_RR_LEVEL = {1: "DEBUG", 2: "INFO", 3: "WARN", 4: "ERROR", 5: "CRITICAL"}
SIDE_BY_SIDE = 5  # node columns (+ bus load) in one row; more go in a grid to stay readable
LOAD_WINDOW = 0.1  # seconds per bus load value
ABSOLUTE_AFTER = 1e8  # seconds: times beyond ~1973 are taken as Unix epoch


def _time(rr, t: np.ndarray, absolute: bool):
    t = np.asarray(t, np.float64)
    if absolute:
        return rr.TimeColumn(TIMELINE, timestamp=t)
    return rr.TimeColumn(TIMELINE, duration=t)


def blueprint_for(
    pdos: Iterable[tuple[str, int, str, int]],
    lanes: Iterable[tuple[str, int]],
    drives: Iterable[tuple[str, int]] = (),
    loads: Iterable[str] = (),
):
    """A column of plots per node (one plot per PDO), the NMT state lanes, the event log.

    pdos: (bus, node, pdo name, COB-ID) of each PDO with signals; lanes: (bus, node) of
    each node with NMT states (live sessions resend the layout as either grows); drives:
    (bus, node) of CiA 402 drives with a state lane; loads: the bus load entities. Bus ""
    on a log of one bus. One plot per PDO
    rather than per node: a node's PDOs often mix units (digital input bytes next to
    analogue millivolts) and a shared axis flattens the small ones. Lanes are named
    one by one: a `/node/*/nmt` pattern matched nothing in the viewer.
    """
    import rerun.blueprint as rrb

    by_node: dict[tuple[str, int], list[tuple[str, int]]] = {}
    for bus, node, pdo, cob_id in sorted(pdos):
        by_node.setdefault((bus, node), []).append((pdo, cob_id))
    columns = [
        rrb.Vertical(
            *[
                rrb.TimeSeriesView(
                    origin=on_bus(bus or None, signal_path(n, pdo)),
                    name=f"{_who(bus, n)} {pdo.upper()} (0x{cob_id:03X})" if n >= 0 else pdo,
                )
                for pdo, cob_id in series
            ],
            name=_who(bus, n) if n >= 0 else f"{bus} DBC".lstrip(),
        )
        for (bus, n), series in by_node.items()
    ]
    loads = sorted(loads)
    if all(p == "/bus/load" for p in loads):
        columns.append(rrb.TimeSeriesView(origin="/bus", name="bus load"))
    else:  # several buses: a line each in one plot
        columns.append(
            rrb.TimeSeriesView(origin="/", contents=[f"+ {p}" for p in loads], name="bus load")
        )
    paths = [on_bus(bus or None, f"/node/{n}/nmt") for bus, n in sorted(lanes)]
    drives = sorted(drives)
    paths += [on_bus(bus or None, f"/node/{n}/drive_state") for bus, n in drives]
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(*columns) if len(columns) <= SIDE_BY_SIDE else rrb.Grid(*columns),
            rrb.StateTimelineView(
                origin="/node" if all(p.startswith("/node/") for p in paths) else "/",
                contents=[f"+ {p}" for p in paths] or "$origin/**",
                name="NMT and drive states" if drives else "NMT states",
            ),
            rrb.TextLogView(origin="/events", name="events", **_log_columns(rrb)),
            row_shares=[3, 1, 2],
        ),
        collapse_panels=True,
    )


def _who(bus: str, node: int) -> str:
    return f"{bus} node {node}" if bus else f"node {node}"


class Layout:
    """What the blueprint names, gathered as batches are sent: a changed layout is sent
    again (live) or once at the end (export)."""

    def __init__(self) -> None:
        self.pdos: set[tuple[str, int, str, int]] = set()
        self.lanes: set[tuple[str, int]] = set()
        self.drives: set[tuple[str, int]] = set()
        self.loads: set[str] = set()

    def add(self, cap: Capture) -> bool:
        """Take in a sent Capture's PDOs, lanes and drives; True when the layout grew."""
        before = (len(self.pdos), len(self.lanes), len(self.drives))
        self.pdos |= {(s.bus or "", s.node, s.pdo, s.cob_id) for s in cap.series}
        self.lanes |= {(e.bus or "", e.node) for e in cap.state_changes}
        self.drives |= {(c.bus or "", c.node) for c in cap.drive_changes if c.kind == "state"}
        return before != (len(self.pdos), len(self.lanes), len(self.drives))

    def blueprint(self):
        return blueprint_for(self.pdos, self.lanes, self.drives, self.loads)


def _log_columns(rrb) -> dict:
    """Time, level and text; the entity path column only ever said "/events".

    The column settings are marked unstable in rerun, so any other version just
    gets the viewer's default columns.
    """
    try:
        from rerun.blueprint.encodings import TextLogColumn, TimelineColumn

        return {
            "columns": rrb.TextLogColumns(
                timeline_columns=[TimelineColumn(TIMELINE)],
                text_log_columns=[
                    TextLogColumn("loglevel"),
                    TextLogColumn("body"),
                    TextLogColumn("entitypath", visible=False),
                ],
            )
        }
    except (ImportError, AttributeError, TypeError, ValueError):
        return {}


def is_absolute(t: np.ndarray) -> bool:
    return bool(t.size and t[0] > ABSOLUTE_AFTER)


def send_header(rec, source: str, network: str) -> None:
    import rerun as rr

    rec.log(
        "/",
        rr.AnyValues(cananalyze_version=__version__, source=source, network=network),
        static=True,
    )


def send_parts(cap: Capture, rec, absolute: bool, counts: dict[str, int], named: set[str]) -> None:
    """Signals, NMT state lanes and events of `cap`; series names only once per path (`named`)."""
    import rerun as rr

    for s in cap.series:
        for name, values in s.columns.items():
            path = on_bus(s.bus, f"{signal_path(s.node, s.pdo)}/{name}")
            if path not in named:
                unit = s.units.get(name)
                rec.log(
                    path, rr.SeriesLines(names=f"{name} [{unit}]" if unit else name), static=True
                )
                named.add(path)
            v = np.asarray(values, np.float64)
            rec.send_columns(
                path, indexes=[_time(rr, s.t, absolute)], columns=rr.Scalars.columns(scalars=v)
            )
            counts[path] = counts.get(path, 0) + int(v.size)
    lanes: dict[str, list[tuple[float, str]]] = {}
    for e in sorted(cap.state_changes, key=lambda e: (e.bus or "", e.node)):
        lanes.setdefault(on_bus(e.bus, f"/node/{e.node}/nmt"), []).append((e.t, e.message))
    for c in sorted(cap.drive_changes, key=lambda c: (c.bus or "", c.node)):
        if c.kind == "state":
            path = on_bus(c.bus, f"/node/{c.node}/drive_state")
            lanes.setdefault(path, []).append((c.t, c.name))
    for path, changes in lanes.items():
        rec.send_columns(
            path,
            indexes=[_time(rr, np.array([t for t, _ in changes]), absolute)],
            columns=rr.StateChange.columns(state=[state for _, state in changes]),
        )
        counts[path] = counts.get(path, 0) + len(changes)
    events = cap.sorted_events()
    if events:
        rec.send_columns(
            "/events",
            indexes=[_time(rr, np.array([e.t for e in events]), absolute)],
            columns=rr.TextLog.columns(
                text=[e.message if e.bus is None else f"{e.bus} {e.message}" for e in events],
                level=[_RR_LEVEL[e.level] for e in events],
            ),
        )
        counts["/events"] = counts.get("/events", 0) + len(events)


def send_load(
    rec,
    bus: str | None,
    starts: np.ndarray,
    load: np.ndarray,
    absolute: bool,
    bitrate: int | None,
    counts: dict[str, int],
    named: set[str],
) -> str:
    """One bus's load series: /bus/load, or /can1/bus/load of several (bus "can1").
    Returns its entity path."""
    import rerun as rr

    path = on_bus(bus, "/bus/load")
    if not load.size:
        return path
    if path not in named:
        name = "bus load [%]" if bitrate else "bus load [bit/s]"
        rec.log(path, rr.SeriesLines(names=name if bus is None else f"{bus} {name}"), static=True)
        named.add(path)
    rec.send_columns(
        path, indexes=[_time(rr, starts, absolute)], columns=rr.Scalars.columns(scalars=load)
    )
    counts[path] = counts.get(path, 0) + int(load.size)
    return path


def recording(name: str):
    """A RecordingStream named after the log (every cananalyze recording is made here)."""
    import rerun as rr

    rec = rr.RecordingStream("cananalyze", send_properties=True)
    rec.send_recording_name(name)
    return rec


def grpc_url(connect: str) -> str:
    """A running viewer's gRPC URL from `--connect` (a URL, or host:port)."""
    return connect if "://" in connect else f"rerun+http://{connect}/proxy"
