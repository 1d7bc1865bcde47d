"""The event log: rare traffic and records of a batch as events, built once for every output.

`Collector` (the Capture, MCAP, rerun) and the streaming table writer both call
`batch_events`, so the events table says the same thing whichever path wrote it.
EMCY, NMT and boot-up texts come from the frame bytes directly, not through
`DecodedBatch.fields` (which realises every lazy SDO note of the batch and
builds a dict per row); rows carrying a note (a profile's manufacturer
decoding) take the full `frame_fields` + `annotation` route, so the text is the
one `decode` prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .decoded import DecodedBatch
from .frames import FLAG_RTR
from .protocol.fields import annotation, frame_fields
from .protocol.services import Service
from .protocol.tables import NMT_COMMANDS, NMT_STATES, emcy_class, error_register_names

# foxglove.Log levels, used for every event (MCAP, rerun, the events table).
DEBUG, INFO, WARNING, ERROR, FATAL = 1, 2, 3, 4, 5
LEVEL_NAMES = {DEBUG: "debug", INFO: "info", WARNING: "warning", ERROR: "error", FATAL: "fatal"}
_LEVEL_BY_NAME = {v: k for k, v in LEVEL_NAMES.items()} | {"critical": FATAL, "warn": WARNING}

_STATE_SERVICES = np.array((Service.HEARTBEAT, Service.BOOTUP, Service.GUARD_RESPONSE), np.uint8)
_EVENT_SERVICES = np.array([Service.NMT, Service.EMCY, Service.BOOTUP], np.uint8)


@dataclass
class Event:
    """One line of the event log: rare traffic or a record, at its time."""

    t: float
    kind: str  # nmt, emcy, bootup, nmt_state, sdo, finding
    node: int | None
    level: int
    message: str
    row: int | None = None


class Row(NamedTuple):
    """An event as a plain tuple (what `batch_events` returns; `Event(*row)` is the same)."""

    t: float
    kind: str
    node: int | None
    level: int
    message: str
    row: int | None


@dataclass
class EventState:
    """What event building carries from batch to batch: each node's last NMT state."""

    last_state: dict[int, str] = field(default_factory=dict)
    last_t: float = 0.0  # time of the last event: a frameless batch's findings default to it


def sdo_message(direction, index, sub, name, result, value, data, abort, detail) -> str:
    """The event text of one SDO record, from its fields (one implementation for dicts and columns)."""
    return _sdo_head(direction, index, sub, name) + _sdo_tail(result, value, data, abort, detail)


def _sdo_head(direction, index, sub, name) -> str:
    if isinstance(index, int) and isinstance(sub, int):
        text = f"SDO {direction} 0x{index:04X}:{sub:02X}"
    else:
        text = f"SDO {direction}"
    return f"{text} {name}" if name else text


def _sdo_tail(result, value, data, abort, detail) -> str:
    ok = result == "ok"
    if ok:
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 9:
            text = (
                f" = {value} (0x{value & 0xFFFFFFFFFFFFFFFF:X}) ok"  # as the text output shows it
            )
        elif value is not None:
            text = f" = {value} ok"
        elif data:
            text = f" data {data} ok"
        else:
            text = " ok"
    else:
        text = f" {result}"
    if abort:
        text += f": {abort}"
    elif not ok and detail:
        text += f": {detail}"
    return text


def sdo_event(row: int, r: dict) -> Row:
    get = r.get
    result = get("result", "?")
    text = sdo_message(
        get("direction", "?"),
        get("index"),
        get("subindex"),
        get("name"),
        result,
        get("value"),
        get("data"),
        get("abort_text"),
        get("detail"),
    )
    level = INFO if result == "ok" else WARNING
    return Row(float(get("t", 0.0)), "sdo", get("node"), level, text, row)


def sdo_events(fields, rows: list[int]) -> list[Row]:
    """`sdo_event` of each fast-path record, from its fields as columns (`RecordColumns`).

    The head ("SDO upload 0x1018:01 name") is formatted once per object and direction:
    a polled bus asks the same few objects over and over.
    """
    c = fields.columns
    heads: dict[tuple, str] = {}
    out: list[Row] = []
    add = out.append
    for t, nd, res, row, d, i, s, nm, v, dat, ab, det in zip(
        c["t"],
        c["node"],
        c["result"],
        rows,
        c["direction"],
        c["index"],
        c["subindex"],
        c["name"],
        c["value"],
        c["data"],
        c["abort_text"],
        c["detail"],
        strict=True,
    ):
        key = (d, i, s, nm)
        head = heads.get(key)
        if head is None:
            head = heads[key] = _sdo_head(d, i, s, nm)
        text = head + _sdo_tail(res, v, dat, ab, det)
        add(Row(t, "sdo", nd, INFO if res == "ok" else WARNING, text, row))
    return out


def finding_event(row: int, r: dict, t: float) -> Row:
    level = r.get("level") or r.get("severity") or "warning"
    lvl = level if isinstance(level, int) else _LEVEL_BY_NAME.get(str(level).lower(), WARNING)
    text = r.get("message") or r.get("text") or r.get("rule") or "finding"
    if r.get("rule") and r.get("message"):
        text = f"[{r['rule']}] {text}"
    return Row(float(r.get("t", t)), "finding", r.get("node"), lvl, str(text), row)


def batch_events(
    batch: DecodedBatch, offset: int, state: EventState
) -> tuple[list[Row], list[Row]]:
    """(events, NMT state changes) of one batch, in the order the Capture has always kept.

    Records first (SDO transactions, findings), then EMCY/NMT/boot-up rows, then
    state changes (only changes, per node, across batches through `state`).
    """
    fb = batch.frames
    n = len(fb)
    last_t = float(fb.t[-1]) if n else state.last_t
    events: list[Row] = []
    split = batch.sdo_fast_split()
    records = batch.records
    if split is None:
        pairs = enumerate(records)
    else:  # the fast path's records as columns; the others read without building those
        get = list.__getitem__
        pairs = ((k, get(records, k)) for k in split[2])
    at: list[int] = []
    for k, (row, rec) in pairs:
        kind = rec.get("kind")
        if kind == "sdo":
            events.append(sdo_event(row + offset, rec))
            at.append(k)
        elif kind == "finding":
            t = float(fb.t[row]) if 0 <= row < n else last_t
            events.append(finding_event(row + offset, rec, t))
            at.append(k)
    if split is not None:
        fields, fast, _ = split
        fast_events = sdo_events(fields, (fast.row + offset).tolist())
        if events:
            order = np.argsort(
                np.concatenate((np.asarray(at, np.int64), fast.slots)), kind="stable"
            )
            both = events + fast_events
            events = list(map(both.__getitem__, order.tolist()))
        else:
            events = fast_events
    states: list[Row] = []
    if n:
        events.extend(_frame_events(batch, offset))
        states = _state_changes(batch, offset, state)
        for ev in states:
            level = INFO if ev.message != "stopped" else WARNING
            message = f"node {ev.node}: NMT state {ev.message}"
            events.append(ev._replace(level=level, message=message))
    if events:
        state.last_t = events[-1].t
    return events, states


_EMCY_HEAD: dict[tuple[int, int], str] = {}


def _emcy_head(code: int, reg: int) -> str:
    """'EMCY 0x8130 ...; register 0x11 [generic,communication]; mfr ' (cached per code/register)."""
    key = (code, reg)
    head = _EMCY_HEAD.get(key)
    if head is None:
        regs = ",".join(error_register_names(reg)) or "none"
        head = f"EMCY 0x{code:04X} {emcy_class(code)}; register 0x{reg:02X} [{regs}]; mfr "
        if len(_EMCY_HEAD) < 65536:
            _EMCY_HEAD[key] = head
    return head


def _frame_events(batch: DecodedBatch, off: int) -> list[Row]:
    """EMCY, NMT and boot-up lines, from columns; rows with a note go through `annotation`."""
    fb = batch.frames
    rows = np.flatnonzero(np.isin(batch.service, _EVENT_SERVICES))
    if rows.size == 0:
        return []
    notes = batch.notes
    # dict.get: a LazyNotes must not realise its SDO notes (they are on SDO rows only)
    noted = {i for i in rows.tolist() if dict.get(notes, i)} if len(dict.keys(notes)) else set()
    out: list[Row] = []
    data = fb.data[rows]
    dlc = fb.dlc[rows].tolist()
    d = data.tolist()
    hexes = None
    for k, (i, s, node, t) in enumerate(
        zip(
            rows.tolist(),
            batch.service[rows].tolist(),
            batch.node[rows].tolist(),
            fb.t[rows].tolist(),
            strict=True,
        )
    ):
        who = node if node >= 0 else None
        if i in noted or i in fb.long_data:
            f = frame_fields(s, fb.payload(i), bool(fb.flags[i] & FLAG_RTR))
            f.update(dict.get(notes, i) or {})
            text = annotation(s, node, int(batch.pdo[i]), f, bool(fb.flags[i] & FLAG_RTR))
            if s == Service.EMCY:
                level, kind = (INFO if f.get("reset") else ERROR), "emcy"
            elif s == Service.NMT:
                level, kind = INFO, "nmt"
            else:
                level, kind = INFO, "bootup"
        elif s == Service.EMCY:
            kind = "emcy"
            b = d[k]
            if dlc[k] < 3:
                level, text = ERROR, "EMCY (malformed: fewer than 3 bytes)"
            else:
                code = b[0] | b[1] << 8
                if code == 0:
                    level, text = INFO, "EMCY error reset / no error"
                else:
                    if hexes is None:
                        hexes = data.tobytes()
                    mfr = hexes[k * 8 + 3 : k * 8 + min(dlc[k], 8)].hex()
                    level, text = ERROR, _emcy_head(code, b[2]) + (mfr or "-")
        elif s == Service.NMT:
            kind, level = "nmt", INFO
            if dlc[k] < 2:
                text = "NMT (malformed: needs 2 bytes)"
            else:
                b = d[k]
                cmd = NMT_COMMANDS.get(b[0]) or f"unknown 0x{b[0]:02X}"
                text = f"NMT {cmd} all nodes" if b[1] == 0 else f"NMT {cmd} node {b[1]}"
        else:
            kind, level, text = "bootup", INFO, "boot-up"
        if node >= 0 and s != Service.NMT:
            text = f"node {node}: {text}"
        out.append(Row(t, kind, who, level, text, i + off))
    return out


def _state_changes(batch: DecodedBatch, off: int, state: EventState) -> list[Row]:
    """NMT state changes per node (heartbeat, boot-up, guarding); message = the state name."""
    fb = batch.frames
    is_state = np.isin(batch.service, _STATE_SERVICES) & (fb.dlc > 0)
    rows = np.flatnonzero(is_state)
    if rows.size == 0:
        return []
    code = fb.data[rows, 0] & 0x7F
    nodes = batch.node[rows]
    out: list[Row] = []
    last = state.last_state
    for n in np.unique(nodes).tolist():
        sel = rows[nodes == n]
        c = code[nodes == n]
        change = np.ones(c.size, bool)
        change[1:] = c[1:] != c[:-1]
        for i, v in zip(sel[change].tolist(), c[change].tolist(), strict=True):
            name = NMT_STATES.get(v, f"unknown 0x{v:02X}")
            if last.get(n) == name:
                continue
            last[n] = name
            out.append(Row(float(fb.t[i]), "nmt_state", n, INFO, name, i + off))
    return out
