"""The event log: rare traffic and records of a batch as events, built once for every output.

The streaming table writer takes them as columns (`batch_event_columns`) and
`Collector` (the Capture, MCAP, rerun) as tuples (`batch_events`, the same
columns), so the events table says the same thing whichever path wrote it.
Texts are built per group, not per event where it can be helped: SDO heads once
per object, EMCY heads once per node/code/register, manufacturer bytes as hex
by numpy.
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

from ..frames import FLAG_RTR
from ..protocol.fields import annotation, frame_fields
from ..protocol.services import Service
from ..protocol.tables import EMCY_CODES, NMT_COMMANDS, NMT_STATES, error_register_names
from ..records import DecodedBatch
from . import columns as ec
from .columns import NO_NODE, EventColumns, Row, texts
from .sdo_text import U64, sdo_head, sdo_message, sdo_messages, sdo_tail

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


@dataclass
class EventState:
    """What event building carries from batch to batch: each node's last NMT state."""

    last_state: dict[int, str] = field(default_factory=dict)
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


def sdo_event_columns(fields, rows: np.ndarray) -> EventColumns:
    """`sdo_event` of each fast-path record as columns, from its fields (`RecordColumns`).

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
        for k, rec in fields.aborted.items():
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
    level = r.get("level") or r.get("severity") or "warning"
    lvl = level if isinstance(level, int) else _LEVEL_BY_NAME.get(str(level).lower(), WARNING)
    text = r.get("message") or r.get("text") or r.get("rule") or "finding"
    if r.get("rule") and r.get("message"):
        text = f"[{r['rule']}] {text}"
    return Row(float(r.get("t", t)), "finding", r.get("node"), lvl, str(text), row)


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
    last_t = float(fb.t[-1]) if n else state.last_t
    split = batch.sdo_fast_split()
    records = batch.records
    if split is None:
        pairs = enumerate(records)
    else:  # the fast path's records as columns; the others read without building those
        get = list.__getitem__
        pairs = ((k, get(records, k)) for k in split[2])
    slow: list[Row] = []
    at: list[int] = []
    for k, (row, rec) in pairs:
        kind = rec.get("kind")
        if kind == "sdo":
            slow.append(sdo_event(row + offset, rec))
            at.append(k)
        elif kind == "finding":
            t = float(fb.t[row]) if 0 <= row < n else last_t
            slow.append(finding_event(row + offset, rec, t))
            at.append(k)
    events = EventColumns.from_rows(slow)
    if split is not None:
        fields, fast, _ = split
        fast_events = sdo_event_columns(fields, fast.row.astype(np.int64) + offset)
        if slow:
            order = np.argsort(
                np.concatenate((np.asarray(at, np.int64), fast.slots)), kind="stable"
            )
            events = EventColumns.concat([events, fast_events]).take(order)
        else:
            events = fast_events
    states: list[Row] = []
    if n:
        parts = [events, _frame_event_columns(batch, offset)]
        states = _state_changes(batch, offset, state)
        if states:
            parts.append(
                EventColumns.from_rows(
                    [
                        ev._replace(
                            level=INFO if ev.message != "stopped" else WARNING,
                            message=f"node {ev.node}: NMT state {ev.message}",
                        )
                        for ev in states
                    ]
                )
            )
        events = EventColumns.concat(parts)
    if len(events):
        state.last_t = float(events.t[-1])
    return events, states


# EMCY text pieces, formatted once per node, error code (at most 65536) and register
_NODE_TEXT: dict[int, str] = {}  # 'node 5: '
_EMCY_CODE_TEXT: dict[int, str] = {}  # 'EMCY 0x8130 Monitoring - ...; register 0x'
_EMCY_REG_TEXT: dict[int, str] = {}  # '11 [generic,communication]; mfr '
_EMCY_CODE_CACHE = 4096  # codes kept in _EMCY_CODE_TEXT at most


def emcy_classes(codes: np.ndarray) -> list[str]:
    """`emcy_class` of each code, by a searchsorted per mask instead of dict probes per code.

    Masks from the least to the most specific, each hit overwriting: the most
    specific name wins, as `emcy_class`'s first hit does.
    """
    keys = np.array(sorted(EMCY_CODES), np.int64)
    names = [EMCY_CODES[k] for k in keys.tolist()] + ["Unknown"]
    pick = np.full(len(codes), len(keys), np.intp)
    for mask in (0xF000, 0xFF00, 0xFFF0, 0xFFFF):
        masked = codes & mask
        at = np.minimum(np.searchsorted(keys, masked), len(keys) - 1)
        hit = keys[at] == masked
        pick[hit] = at[hit]
    return list(map(names.__getitem__, pick.tolist()))


def _emcy_heads(node: list[int], code: list[int], reg: list[int]) -> list[str]:
    """'node 5: EMCY 0x8130 ...; register 0x11 [generic,communication]; mfr ' of each EMCY."""
    for n in set(node).difference(_NODE_TEXT):
        _NODE_TEXT[n] = f"node {n}: " if n >= 0 else ""
    new = sorted(set(code).difference(_EMCY_CODE_TEXT))
    if len(_EMCY_CODE_TEXT) + len(new) > _EMCY_CODE_CACHE:  # random codes (a noisy bus, the
        _EMCY_CODE_TEXT.clear()  # generator) must not fill all 65536 over a long log
        new = sorted(set(code))
    for c, cls in zip(new, emcy_classes(np.array(new, np.int64)), strict=True):
        _EMCY_CODE_TEXT[c] = f"EMCY 0x{c:04X} {cls}; register 0x"
    for r in set(reg).difference(_EMCY_REG_TEXT):
        regs = ",".join(error_register_names(r)) or "none"
        _EMCY_REG_TEXT[r] = f"{r:02X} [{regs}]; mfr "
    add = operator.add
    return list(
        map(
            add,
            map(add, map(_NODE_TEXT.__getitem__, node), map(_EMCY_CODE_TEXT.__getitem__, code)),
            map(_EMCY_REG_TEXT.__getitem__, reg),
        )
    )


_HEX = np.frombuffer(b"0123456789abcdef", np.uint8)


def _any_of(service: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """service in codes, by a comparison per code (twice as fast as a lookup table here)."""
    out = service == codes[0]
    for c in codes[1:]:
        out |= service == c
    return out


def _mfr_hex(data: np.ndarray, dlc: np.ndarray) -> list[str]:
    """EMCY manufacturer bytes (3 up to the DLC) as lowercase hex, '-' when there are none."""
    m = len(dlc)
    byte = data[:, 3:8]
    chars = np.empty((m, 5, 2), np.uint8)
    chars[:, :, 0] = _HEX[byte >> 4]
    chars[:, :, 1] = _HEX[byte & 15]
    chars[np.arange(3, 8) >= np.minimum(dlc, 8)[:, None]] = 0  # trailing NULs: dropped
    out = chars.reshape(m, 10).view("S10").ravel().astype("U10")
    out[out == ""] = "-"
    return out.tolist()


def _marked(keys, n: int) -> np.ndarray:
    """A mask over a batch's n rows, True at the given row numbers (those in range)."""
    at = np.fromiter(keys, np.int64, len(keys))
    mask = np.zeros(n, bool)
    mask[at[(at >= 0) & (at < n)]] = True
    return mask


def _frame_event_columns(batch: DecodedBatch, off: int) -> EventColumns:
    """EMCY, NMT and boot-up lines, from columns; rows with a note go through `annotation`."""
    fb = batch.frames
    rows = np.flatnonzero(_any_of(batch.service, _EVENT_SERVICES))
    m = rows.size
    if m == 0:
        return EventColumns.empty()
    notes = batch.notes
    service = batch.service[rows]
    node = batch.node[rows]
    dlc = fb.dlc[rows]
    data = fb.data[rows]
    kind = np.full(m, ec.BOOTUP, np.uint8)
    kind[service == Service.EMCY] = ec.EMCY
    kind[service == Service.NMT] = ec.NMT
    level = np.full(m, INFO, np.int8)
    text = np.full(m, "boot-up", object)
    # dict.get: a LazyNotes must not realise its SDO notes (they are on SDO rows only)
    slow = np.zeros(m, bool)
    if len(dict.keys(notes)):
        at = np.flatnonzero(_marked(dict.keys(notes), len(fb))[rows]).tolist()
        slow[[k for k, i in zip(at, rows[at].tolist(), strict=True) if dict.get(notes, i)]] = True
    if fb.long_data:
        slow |= _marked(fb.long_data, len(fb))[rows]
    emcy = (kind == ec.EMCY) & ~slow
    prefixed = (node >= 0) & (service != Service.NMT)  # "node 5: " still to prepend
    if emcy.any():
        code = data[:, 0].astype(np.int64) | data[:, 1].astype(np.int64) << 8
        short = emcy & (dlc < 3)
        text[short] = "EMCY (malformed: fewer than 3 bytes)"
        level[short] = ERROR
        reset = emcy & (dlc >= 3) & (code == 0)
        text[reset] = "EMCY error reset / no error"
        err = np.flatnonzero(emcy & (dlc >= 3) & (code != 0))
        if err.size:
            # one head per (node, code, register): a faulty node repeats its EMCY
            key = (node[err].astype(np.int64) + 1) << 24 | code[err] << 8 | data[err, 2]
            uniq, inv = np.unique(key, return_inverse=True)
            heads = _emcy_heads(
                ((uniq >> 24) - 1).tolist(), (uniq >> 8 & 0xFFFF).tolist(), (uniq & 0xFF).tolist()
            )
            heads = texts(heads)[inv.ravel()].tolist()
            text[err] = list(map(operator.add, heads, _mfr_hex(data[err], dlc[err])))
            level[err] = ERROR
            prefixed[err] = False
    for k in np.flatnonzero((kind == ec.NMT) & ~slow).tolist():
        if dlc[k] < 2:
            text[k] = "NMT (malformed: needs 2 bytes)"
        else:
            b0, b1 = int(data[k, 0]), int(data[k, 1])
            cmd = NMT_COMMANDS.get(b0) or f"unknown 0x{b0:02X}"
            text[k] = f"NMT {cmd} all nodes" if b1 == 0 else f"NMT {cmd} node {b1}"
    for k in np.flatnonzero(slow).tolist():
        i, s = int(rows[k]), int(service[k])
        rtr = bool(fb.flags[i] & FLAG_RTR)
        f = frame_fields(s, fb.payload(i), rtr)
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


def _state_changes(batch: DecodedBatch, off: int, state: EventState) -> list[Row]:
    """NMT state changes per node (heartbeat, boot-up, guarding); message = the state name.

    Frames grouped by node (a stable sort keeps each node's frames in order), only
    those whose state differs from the node's previous frame looked at in Python.
    """
    fb = batch.frames
    rows = np.flatnonzero(_any_of(batch.service, _STATE_SERVICES) & (fb.dlc > 0))
    if rows.size == 0:
        return []
    nodes = batch.node[rows]
    order = np.argsort(nodes, kind="stable")
    rows, nodes = rows[order], nodes[order]
    code = fb.data[rows, 0] & 0x7F
    change = np.ones(rows.size, bool)
    change[1:] = (code[1:] != code[:-1]) | (nodes[1:] != nodes[:-1])
    out: list[Row] = []
    last = state.last_state
    sel = rows[change]
    for i, n, v, t in zip(
        sel.tolist(),
        nodes[change].tolist(),
        code[change].tolist(),
        fb.t[sel].tolist(),
        strict=True,
    ):
        name = NMT_STATES.get(v, f"unknown 0x{v:02X}")
        if last.get(n) == name:
            continue
        last[n] = name
        out.append(Row(t, "nmt_state", n, INFO, name, i + off))
    return out
