"""The event log: rare traffic and records of a batch as events, built once for every output.

The streaming table writer takes them as columns (`batch_event_columns`) and
`Collector` (the Capture, MCAP, rerun) as tuples (`batch_events`, the same
columns), so the events table says the same thing whichever path wrote it.
Texts are built per group, not per event where it can be helped: SDO heads once
per object, EMCY texts as byte columns (`protocol.emcy.text_columns`, the text
output's too).
EMCY, NMT and boot-up texts come from the frame bytes directly, not through
`DecodedBatch.fields` (which realises every lazy SDO note of the batch and
builds a dict per row); rows carrying a note (a profile's manufacturer
decoding) take the full `frame_fields` + `annotation` route, so the text is the
one `decode` prints.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass, field
from itertools import repeat

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.core.frames import FLAG_RTR
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.events import columns as ec
from cananalyze.decode.events.columns import NO_NODE, EventColumns, Row, texts
from cananalyze.decode.events.sdo_text import (
    U64,
    record_message,
    sdo_head,
    sdo_messages,
    sdo_tail,
)
from cananalyze.decode.nmt_state import NmtStates
from cananalyze.devices import cia402
from cananalyze.protocol import emcy, nmt
from cananalyze.protocol.fields import annotation, frame_fields
from cananalyze.protocol.services import Service

# foxglove.Log levels, used for every event (MCAP, rerun, the events table).
DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5
LEVEL_NAMES = {DEBUG: "debug", INFO: "info", WARNING: "warning", ERROR: "error", FATAL: "fatal"}
_LEVEL_BY_NAME = {v: k for k, v in LEVEL_NAMES.items()} | {"critical": FATAL, "warn": WARNING}

_NMT_SERVICES = np.array(
    (Service.HEARTBEAT, Service.BOOTUP, Service.GUARD_RESPONSE, Service.NMT), np.uint8
)
_EVENT_SERVICES = np.array([Service.NMT, Service.EMCY, Service.BOOTUP], np.uint8)
_FRAME_SERVICES = np.union1d(_NMT_SERVICES, _EVENT_SERVICES).astype(np.uint8)


@dataclass
class Event:
    """One line of the event log: rare traffic or a record, at its time."""

    t: float
    kind: str  # nmt, emcy, bootup, nmt_state, sdo, finding
    node: int | None
    level: int
    message: str
    row: int | None = None
    bus: str | None = None  # several buses: which one


@dataclass
class EventState:
    """What event building carries from batch to batch: each node's last NMT state."""

    nmt: dict[int, NmtStates] = field(default_factory=dict)  # channel -> its nodes' states
    last_t: float = 0.0  # time of the last event: a frameless batch's findings default to it


class EventBuilder:
    """The event log of each batch, built once for every sink (the pipeline's one state).

    Rows count from the start of what the sinks were given (their frames tables).
    """

    def __init__(self) -> None:
        self.state = EventState()

    def build(self, batch: DecodedBatch, offset: int) -> tuple[EventColumns, list[Row]]:
        return batch_event_columns(batch, offset, self.state)


def sdo_event(row: int, r: dict) -> Row:
    get = r.get
    result = get("result", "?")
    text = record_message(r)
    level = INFO if result == "ok" else WARNING
    return Row(float(get("t", 0.0)), "sdo", get("node"), level, text, row)


def sdo_event_columns(fields, rows: np.ndarray) -> EventColumns:
    """`sdo_event` of each record as columns, from its fields (`RecordColumns`).

    When every value decoded is an integer (the usual case) the texts are built as
    byte columns (`sdo_messages`). Otherwise the head ("SDO upload 0x1018:01 name")
    is formatted once per object and direction, an integer answer ("... = 305419896
    (0x12345678) ok") takes one f-string with the head, every other one `sdo_tail`.
    """
    messages = sdo_messages(fields)
    if messages is not None:  # columns: no per-field lists, no f-string per record
        a = fields.arrays
        n = len(fields)
        t = np.array(a["t"], np.float64)
        node = a["node"].astype(np.int16)
        ok = np.ones(n, bool)
        for k, rec in fields.held.items():
            t[k] = rec.get("t", t[k])
            node[k] = NO_NODE if rec.get("node") is None else rec["node"]
            ok[k] = rec.get("result") == "ok"
        return EventColumns(
            t,
            np.full(n, ec.SDO, np.uint8),
            node,
            np.where(ok, INFO, WARNING).astype(np.int8),
            texts(messages),
            rows,
        )
    c = fields.columns
    n = len(c["t"])
    result = c["result"]
    ok = np.fromiter(map(operator.eq, result, repeat("ok", n)), bool, n)
    keys = list(zip(c["direction"], c["index"], c["subindex"], c["name"], strict=True))
    heads = {k: sdo_head(*k) for k in dict.fromkeys(keys)}
    messages = [
        f"{h} = {v} (0x{v:X}) ok"  # = sdo_tail's text for these (v & 2**64-1 == v)
        if type(v) is int and 9 < v <= U64 and r == "ok" and a is None
        else h + sdo_tail(r, v, d, a, det)
        for h, r, v, d, a, det in zip(
            map(heads.__getitem__, keys),
            result,
            c["value"],
            c["data"],
            c["abort_text"],
            c["detail"],
            strict=True,
        )
    ]
    return EventColumns(
        np.array(c["t"], np.float64),
        np.full(n, ec.SDO, np.uint8),
        _int_column(c["node"], np.int16, NO_NODE),
        np.where(ok, INFO, WARNING).astype(np.int8),
        texts(messages),
        rows,
    )


def _int_column(values: list, dtype, none: int) -> np.ndarray:
    """An integer column of a list of int/None, `none` for None."""
    try:
        return np.array(values, dtype)
    except TypeError:
        return np.array([none if v is None else v for v in values], dtype)


def finding_event(row: int, r: dict, t: float) -> Row:
    return Row(*_finding_fields(r, t, row))


def _finding_fields(r: dict, t: float, row: int) -> tuple:
    """(t, kind, node, level, message, row) of a finding record's event."""
    get = r.get
    level = get("level") or get("severity") or "warning"
    lvl = level if isinstance(level, int) else _LEVEL_BY_NAME.get(str(level).lower(), WARNING)
    text = get("message") or get("text") or get("rule") or "finding"
    if get("rule") and get("message"):
        text = f"[{r['rule']}] {text}"
    return float(get("t", t)), "finding", get("node"), lvl, str(text), row


def finding_event_columns(found, offset: int) -> EventColumns:
    """A batch's findings (`FindingColumns`) as events: "[rule] message" at the finding's
    time, its level from the severity."""
    n = len(found)
    if n == 0:
        return EventColumns.empty()
    rules, sev = found.column("rule"), found.column("severity")
    levels = {s: _LEVEL_BY_NAME.get(str(s).lower(), WARNING) for s in set(sev)}
    messages = found.messages()
    if set(map(type, rules)) == {str} == set(map(type, messages)) and all(rules) and all(messages):
        # the usual case, "[rule] message" without a format per row: the rule's prefix
        # (a few distinct) and the message put together by numpy's object add
        prefix = {r: f"[{r}] " for r in set(rules)}
        text = texts(list(map(prefix.__getitem__, rules))) + texts(messages)
    else:
        text = texts(
            [
                f"[{r}] {m}" if r and m else str(m or r or "finding")
                for r, m in zip(rules, messages, strict=True)
            ]
        )
    times = found.times()
    return EventColumns(
        times[0].copy() if times is not None else np.asarray(found.column("t"), np.float64),
        np.full(n, ec.FINDING, np.uint8),
        found.node.astype(np.int16),  # -1: no node, as NO_NODE
        np.array([levels[s] for s in sev], np.int8),
        text,
        found.row + offset,
    )


def batch_events_of(
    batch: DecodedBatch, offset: int, state: EventState
) -> tuple[EventColumns, list[Row]]:
    """The batch's events as the pipeline built them for every sink; built here (with the
    caller's own state) only for a batch that did not come through the pipeline."""
    if batch.events is not None:
        return batch.events, batch.states
    return batch_event_columns(batch, offset, state)


def batch_events(
    batch: DecodedBatch, offset: int, state: EventState
) -> tuple[list[Row], list[Row]]:
    """(events, NMT state changes) of one batch as tuples (the Capture, MCAP, rerun)."""
    events, states = batch_event_columns(batch, offset, state)
    return events.rows(), states


def batch_event_columns(
    batch: DecodedBatch, offset: int, state: EventState
) -> tuple[EventColumns, list[Row]]:
    """(events as columns, NMT state changes) of one batch, in the order the Capture keeps.

    Records first (SDO transactions, findings), then EMCY/NMT/boot-up rows, then
    state changes (only changes, per node, across batches through `state`).
    """
    fb = batch.frames
    n = len(fb)
    several = batch.several
    records = batch.records
    events = EventColumns.empty()
    if records:
        fields = records.fields()
        events = sdo_event_columns(fields, np.asarray(records.rows, np.int64) + offset)
        other = [k for k, rec in fields.held.items() if rec.get("kind") != "sdo"]
        at = np.arange(len(fields), dtype=np.int64)
        if other:  # (hand-made records of another kind: no event)
            at = np.delete(at, sorted(other))
            events = events.take(at)
        if several:
            events.bus = batch.record_buses(at)
    if len(batch.findings):  # after every record, as the Checker adds them last
        found = finding_event_columns(batch.findings, offset)
        if several:
            found.bus = np.asarray(batch.findings.column("bus"), object)
        events = EventColumns.concat([events, found])
    states: list[Row] = []
    if n:
        # one scan of the batch for the rows of both (a few percent of it), each then
        # picks its own from those
        rows = np.flatnonzero(_any_of(batch.service, _FRAME_SERVICES))
        parts = [events, _frame_event_columns(batch, offset, rows)]
        states = _state_changes(batch, offset, state, rows)
        if states:
            parts.append(
                EventColumns.from_rows(
                    [
                        ev._replace(
                            level=WARNING if ev.message == nmt.STATES[nmt.STOPPED] else INFO,
                            message=f"node {ev.node}: NMT state {ev.message}",
                        )
                        for ev in states
                    ]
                )
            )
        if several:
            for part in parts[1:]:
                part.bus = batch.row_buses(part.row - offset)
            at = np.array([r.row - offset for r in states], np.int64)
            states = [r._replace(bus=b) for r, b in zip(states, batch.row_buses(at), strict=True)]
        events = EventColumns.concat(parts)
    if batch.drive:
        drive = drive_event_columns(batch.drive, offset)
        if several:
            drive.bus = batch.row_buses(drive.row - offset)
        events = EventColumns.concat([events, drive])
    if batch.commissioning:  # boot stories and LSS steps (decode/commissioning)
        done = EventColumns.from_rows(
            [c[:5] + (None if c.row is None else c.row + offset,) for c in batch.commissioning]
        )
        if several:
            done.bus = np.array([c.bus for c in batch.commissioning], object)
        events = EventColumns.concat([events, done])
    if len(events):
        state.last_t = float(events.t[-1])
    return events, states


_DRIVE_LEVEL = {cia402.FAULT: ERROR, cia402.FAULT_REACTION: ERROR, cia402.QUICK_STOP: WARNING}


def drive_event_columns(changes: list, offset: int) -> EventColumns:
    """CiA 402 state changes and new commands (`network.drive_tracker`) as events."""
    rows = [
        Row(
            c.t,
            "drive_state" if c.kind == "state" else "drive_command",
            c.node,
            _DRIVE_LEVEL.get(c.code, INFO) if c.kind == "state" else INFO,
            c.text(),
            c.row + offset,
        )
        for c in changes
        if c.kind in ("state", "command")
    ]
    return EventColumns.from_rows(rows)


def _any_of(service: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """service in codes, by a comparison per code (twice as fast as a lookup table here)."""
    out = service == codes[0]
    for c in codes[1:]:
        out |= service == c
    return out


def _marked(keys, n: int) -> np.ndarray:
    """A mask over a batch's n rows, True at the given row numbers (those in range)."""
    at = np.fromiter(keys, np.int64, len(keys))
    mask = np.zeros(n, bool)
    mask[at[(at >= 0) & (at < n)]] = True
    return mask


# "node 5: " of each node-ID, row k + 1 (row 0: no node), NUL-padded
_NODE_PREFIX = bytecols.padded_table([b"", *(f"node {k}: ".encode() for k in range(128))])


def _node_prefix(nodes: np.ndarray) -> np.ndarray:
    """The "node 5: " of each row as a NUL-padded byte block (nothing for a row without a node)."""
    if nodes.size and int(nodes.min()) >= -1 and int(nodes.max()) <= 127:
        return _NODE_PREFIX[nodes.astype(np.intp) + 1]  # (the padding is dropped when joined)
    u, at = np.unique(nodes, return_inverse=True)
    table = bytecols.padded_table([f"node {k}: ".encode() if k >= 0 else b"" for k in u.tolist()])
    return table[at.reshape(-1)]


def _frame_event_columns(batch: DecodedBatch, off: int, near: np.ndarray) -> EventColumns:
    """EMCY, NMT and boot-up lines, from columns; rows with a note go through `annotation`.

    near: the batch's rows of any of _FRAME_SERVICES."""
    fb = batch.frames
    rows = near[_any_of(batch.service[near], _EVENT_SERVICES)]
    m = rows.size
    if m == 0:
        return EventColumns.empty()
    notes = batch.notes
    service = batch.service[rows]
    node = batch.node[rows]
    dlc = fb.dlc[rows]
    data = np.take(fb.data, rows, axis=0)  # (~10x numpy's 2-D fancy indexing)
    kind = np.full(m, ec.BOOTUP, np.uint8)
    kind[service == Service.EMCY] = ec.EMCY
    kind[service == Service.NMT] = ec.NMT
    level = np.full(m, INFO, np.int8)
    text = np.empty(m, object)  # every row is set below (np.full of an object is slow)
    text[kind == ec.BOOTUP] = nmt.BOOTUP_TEXT
    # dict.get: a LazyNotes must not realise its SDO notes (they are on SDO rows only)
    slow = np.zeros(m, bool)
    if len(dict.keys(notes)):
        at = np.flatnonzero(_marked(dict.keys(notes), len(fb))[rows]).tolist()
        slow[[k for k, i in zip(at, rows[at].tolist(), strict=True) if dict.get(notes, i)]] = True
    if fb.long_data:
        slow |= _marked(fb.long_data, len(fb))[rows]
    prefixed = (node >= 0) & (service != Service.NMT)  # "node 5: " still to prepend
    at = np.flatnonzero((kind == ec.EMCY) & ~slow)
    if at.size:  # "node 5: " in the same byte columns, not one format per event after
        raised = np.take(data, at, axis=0)
        parts = [_node_prefix(node[at]), *emcy.text_columns(raised, dlc[at])]
        text[at] = bytecols.joined_rows(parts, at.size)
        prefixed[at] = False
        reset = (dlc[at] >= emcy.MIN_BYTES) & (raised[:, 0] == 0) & (raised[:, 1] == 0)
        level[at[~reset]] = ERROR
    for k in np.flatnonzero((kind == ec.NMT) & ~slow).tolist():
        text[k] = nmt.command_text(nmt.command_fields(bytes(data[k, : dlc[k]])))
    for k in np.flatnonzero(slow).tolist():
        i, s = int(rows[k]), int(service[k])
        rtr = bool(fb.flags[i] & FLAG_RTR)
        f = frame_fields(s, fb.payload(i), rtr, int(fb.can_id[i]))
        f.update(dict.get(notes, i) or {})
        text[k] = annotation(s, int(node[k]), int(batch.pdo[i]), f, rtr)
        if s == Service.EMCY:
            level[k] = INFO if f.get("reset") else ERROR
    named = np.flatnonzero(prefixed)
    if named.size:
        text[named] = list(
            map(
                "node {}: {}".format,
                node[named].tolist(),
                text[named].tolist(),
            )
        )
    return EventColumns(
        fb.t[rows],
        kind,
        np.where(node >= 0, node, NO_NODE).astype(np.int16),
        level,
        text,
        rows.astype(np.int64) + off,
    )


def _state_changes(batch: DecodedBatch, off: int, state: EventState, near: np.ndarray) -> list[Row]:
    """NMT state changes per node, as `NmtStates` follows them (heartbeats, guard
    responses, boot-ups and NMT commands: the states the checks judge by), one
    `NmtStates` per bus (node 5 on can1 is another device than node 5 on can0);
    message = the state name, row = the frame that made the change."""
    fb = batch.frames
    rows = near[_any_of(batch.service[near], _NMT_SERVICES)]
    if rows.size == 0:
        return []
    channel = fb.channel[rows]
    out: list[Row] = []
    buses = np.flatnonzero(np.bincount(channel)).tolist()  # (small codes: no sort)
    for c in buses:
        mine = rows if len(buses) == 1 else rows[channel == c]
        follow = state.nmt.setdefault(int(c), NmtStates())
        for row, t, node, v in follow.changes(batch, mine, c):
            out.append(Row(t, "nmt_state", node, INFO, nmt.state_name(v), row + off))
    if len(buses) > 1:
        out.sort(key=lambda r: (r.t, r.row))  # several buses: as each bus's, time then file order
    return out
