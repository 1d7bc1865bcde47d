"""What a Rerun recording holds: PDO signals as plots, NMT states as lanes, events as a
text log, and its layout. Sent batch by batch by `stream.StreamRrd` (export, decode)
and `live.RerunLive` (live sessions).

Entities:
  /node/<N>/<pdo>/<signal>  Scalars (series named "signal [unit]")
  /node/<N>/nmt             StateChange lane (heartbeat, boot-up, guarding)
  /node/<N>/drive_state     StateChange lane of a CiA 402 drive (its statusword)
  /events                   TextLog with levels (SDO, EMCY, NMT, findings)
  /bus/load                 Scalars: bits/s, or percent with a bitrate
Everything is sent with `send_columns`, one call per series, never one `log` per
frame, so a million-frame log exports in about a second. Time is the `time`
timeline: a timestamp when the log has absolute (epoch) times, else a duration.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ... import __version__
from ...capture import Capture
from ...records import signal_path

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
    pdos: Iterable[tuple[int, str, int]],
    lane_nodes: Iterable[int],
    drive_nodes: Iterable[int] = (),
):
    """A column of plots per node (one plot per PDO), the NMT state lanes, the event log.

    pdos: (node, pdo name, COB-ID) of each PDO with signals; lane_nodes: nodes with
    NMT states (live sessions resend the layout as either grows); drive_nodes: CiA 402
    drives with a state lane. One plot per PDO
    rather than per node: a node's PDOs often mix units (digital input bytes next to
    analogue millivolts) and a shared axis flattens the small ones. Lanes are named
    one by one: a `/node/*/nmt` pattern matched nothing in the viewer.
    """
    import rerun.blueprint as rrb

    by_node: dict[int, list[tuple[str, int]]] = {}
    for node, pdo, cob_id in sorted(pdos):
        by_node.setdefault(node, []).append((pdo, cob_id))
    columns = [
        rrb.Vertical(
            *[
                rrb.TimeSeriesView(
                    origin=signal_path(n, pdo),
                    name=f"node {n} {pdo.upper()} (0x{cob_id:03X})" if n >= 0 else pdo,
                )
                for pdo, cob_id in series
            ],
            name=f"node {n}" if n >= 0 else "DBC",
        )
        for n, series in by_node.items()
    ]
    columns.append(rrb.TimeSeriesView(origin="/bus", name="bus load"))
    lanes = [f"+ /node/{n}/nmt" for n in sorted(lane_nodes)]
    drive_nodes = sorted(drive_nodes)
    lanes += [f"+ /node/{n}/drive_state" for n in drive_nodes]
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(*columns) if len(columns) <= SIDE_BY_SIDE else rrb.Grid(*columns),
            rrb.StateTimelineView(
                origin="/node",
                contents=lanes or "$origin/**",
                name="NMT and drive states" if drive_nodes else "NMT states",
            ),
            rrb.TextLogView(origin="/events", name="events", **_log_columns(rrb)),
            row_shares=[3, 1, 2],
        ),
        collapse_panels=True,
    )


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
            path = f"{signal_path(s.node, s.pdo)}/{name}"
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
    by_node: dict[int, list] = {}
    for e in cap.state_changes:
        by_node.setdefault(e.node, []).append(e)
    for node, evs in sorted(by_node.items()):
        path = f"/node/{node}/nmt"
        rec.send_columns(
            path,
            indexes=[_time(rr, np.array([e.t for e in evs]), absolute)],
            columns=rr.StateChange.columns(state=[e.message for e in evs]),
        )
        counts[path] = counts.get(path, 0) + len(evs)
    drives: dict[int, list] = {}
    for c in cap.drive_changes:
        if c.kind == "state":
            drives.setdefault(c.node, []).append(c)
    for node, cs in sorted(drives.items()):
        path = f"/node/{node}/drive_state"
        rec.send_columns(
            path,
            indexes=[_time(rr, np.array([c.t for c in cs]), absolute)],
            columns=rr.StateChange.columns(state=[c.name for c in cs]),
        )
        counts[path] = counts.get(path, 0) + len(cs)
    events = cap.sorted_events()
    if events:
        rec.send_columns(
            "/events",
            indexes=[_time(rr, np.array([e.t for e in events]), absolute)],
            columns=rr.TextLog.columns(
                text=[e.message for e in events], level=[_RR_LEVEL[e.level] for e in events]
            ),
        )
        counts["/events"] = counts.get("/events", 0) + len(events)


def send_load(
    rec,
    starts: np.ndarray,
    load: np.ndarray,
    absolute: bool,
    bitrate: int | None,
    counts: dict[str, int],
    named: set[str],
) -> None:
    import rerun as rr

    if not load.size:
        return
    if "/bus/load" not in named:
        name = "bus load [%]" if bitrate else "bus load [bit/s]"
        rec.log("/bus/load", rr.SeriesLines(names=name), static=True)
        named.add("/bus/load")
    rec.send_columns(
        "/bus/load", indexes=[_time(rr, starts, absolute)], columns=rr.Scalars.columns(scalars=load)
    )
    counts["/bus/load"] = counts.get("/bus/load", 0) + int(load.size)


def recording(name: str):
    """A RecordingStream named after the log (every cananalyze recording is made here)."""
    import rerun as rr

    rec = rr.RecordingStream("cananalyze", send_properties=True)
    rec.send_recording_name(name)
    return rec


def grpc_url(connect: str) -> str:
    """A running viewer's gRPC URL from `--connect` (a URL, or host:port)."""
    return connect if "://" in connect else f"rerun+http://{connect}/proxy"
