"""The event log built as columns (`batch_event_columns`, `EventColumns`) says what the
per-row route says: `sdo_event`/`finding_event` over the records as dicts, `frame_fields`
+ `annotation` for every EMCY/NMT/boot-up frame, a plain loop of CiA 301's NMT state
machine for the state changes.
Checked on real logs with EMCY/NMT/boot-up traffic, the samples, and generated traffic
with repeated and distinct EMCY payloads, malformed frames, aborts, NMT and boot-ups; the
boot stories and LSS steps of the decoder's commissioning processor come last, as they are."""

from __future__ import annotations

import bisect

import numpy as np
import pytest
from conftest import SAMPLES, real_file
from exported import DEVICES, decoded_batches

from cananalyze.core.frames import FLAG_RTR, FrameBatch, concat
from cananalyze.decode.events.build import (
    ERROR,
    INFO,
    WARNING,
    EventState,
    batch_event_columns,
    batch_events,
    finding_event,
    sdo_event,
)
from cananalyze.decode.events.columns import NO_NODE, NO_ROW, EventColumns, Row
from cananalyze.formats.source import open_log
from cananalyze.outputs.tables.stream import HOLD
from cananalyze.outputs.tables.stream import TableSink as StreamTables
from cananalyze.pipeline import Options, build_decoder
from cananalyze.protocol.fields import annotation, frame_fields
from cananalyze.protocol.nmt import state_name
from cananalyze.protocol.services import Service


def _reference(batch, off: int, state: dict) -> tuple[list[Row], list[Row]]:
    """Every event of a batch, one row at a time (the route `decode` prints)."""
    fb = batch.frames
    n = len(fb)
    events: list[Row] = []
    for row, rec in list(batch.records):  # the dicts, whatever the fast path kept
        if rec.get("kind") == "sdo":
            events.append(sdo_event(row + off, rec))
        elif rec.get("kind") == "finding":
            t = float(fb.t[row]) if 0 <= row < n else state["t"]
            events.append(finding_event(row + off, rec, t))
    for f in batch.findings:  # the Checker's findings (columns), after every record
        events.append(finding_event(f.row + off, f.record(), f.t))
    levels = {Service.EMCY: ERROR, Service.NMT: INFO, Service.BOOTUP: INFO}
    kinds = {Service.EMCY: "emcy", Service.NMT: "nmt", Service.BOOTUP: "bootup"}
    for i in range(n):
        s = int(batch.service[i])
        if s not in kinds:
            continue
        node = int(batch.node[i])
        rtr = bool(fb.flags[i] & FLAG_RTR)
        f = frame_fields(s, fb.payload(i), rtr)
        f.update(dict.get(batch.notes, i) or {})
        text = annotation(s, node, int(batch.pdo[i]), f, rtr)
        if node >= 0 and s != Service.NMT:
            text = f"node {node}: {text}"
        level = INFO if s == Service.EMCY and f.get("reset") else levels[s]
        who = node if node >= 0 else None
        events.append(Row(float(fb.t[i]), kinds[s], who, level, text, i + off))
    states: list[Row] = []
    # NMT states, one frame at a time in time then file order: a boot-up means
    # pre-operational, a heartbeat or guard response its state, an NMT command the
    # state it commands (node 0: every node known so far); a change is told once the
    # node has sent a frame of its own
    sent = {Service.HEARTBEAT, Service.TPDO, Service.EMCY, Service.SDO_RESPONSE}
    sent |= {Service.GUARD_RESPONSE, Service.BOOTUP}
    for i in range(n):
        if batch.service[i] in sent and 0 <= batch.node[i] < 128:
            state["heard"].setdefault((int(fb.channel[i]), int(batch.node[i])), (off, i))
    commands = {0x01: 5, 0x02: 4, 0x80: 0x7F, 0x81: 0, 0x82: 0}
    kinds = (Service.HEARTBEAT, Service.GUARD_RESPONSE, Service.BOOTUP, Service.NMT)
    rows = sorted((float(fb.t[i]), i) for i in range(n) if batch.service[i] in kinds)
    for t, i in rows:
        s, ch = int(batch.service[i]), int(fb.channel[i])
        cur = state["last"].setdefault(ch, {})
        if s == Service.NMT:
            if fb.dlc[i] < 2 or int(fb.data[i, 0]) not in commands or fb.data[i, 1] >= 128:
                continue
            target, v, src = int(fb.data[i, 1]), commands[int(fb.data[i, 0])], "nmt"
        else:
            target, src = int(batch.node[i]), ("bootup" if s == Service.BOOTUP else "report")
            v = 0x7F if s == Service.BOOTUP else int(fb.data[i, 0]) & 0x7F
        for k in list(cur) if target == 0 else [target]:
            if cur.get(k) == v and src != "bootup":
                continue
            cur[k] = v
            if state["heard"].get((ch, k), (off + 1, n)) <= (off, i):
                states.append(Row(t, "nmt_state", k, INFO, state_name(v), i + off))
    for ev in states:
        level = WARNING if ev.message == "stopped" else INFO
        events.append(ev._replace(level=level, message=f"node {ev.node}: NMT state {ev.message}"))
    for c in batch.commissioning:  # LSS steps and boot stories (decode/commissioning), last
        row = None if c.row is None else c.row + off
        events.append(Row(c.t, c.kind, c.node, c.level, c.message, row))
    if events:
        state["t"] = events[-1].t
    elif n:
        state["t"] = float(fb.t[-1])
    return events, states


def _assert_same_events(batches) -> int:
    state = EventState()
    ref_state = {"last": {}, "t": 0.0, "heard": {}}
    off = count = 0
    for batch in batches:
        events, states = batch_events(batch, off, state)
        ref_events, ref_states = _reference(batch, off, ref_state)
        assert events == ref_events
        assert states == ref_states
        assert [type(v) for e in events for v in e] == [type(v) for e in ref_events for v in e]
        count += len(events)
        off += len(batch)
    return count


def _emcy_bus(n: int = 6000, seed: int = 5) -> FrameBatch:
    """EMCY (repeated and distinct payloads, resets, short), NMT, boot-ups, heartbeats, SDO."""
    rng = np.random.default_rng(seed)
    fb = FrameBatch.allocate(n, ("can0",))
    fb.t[:] = 1000.0 + np.cumsum(rng.integers(50, 5000, n)) / 1e6
    kind = rng.choice(7, n, p=[0.3, 0.15, 0.1, 0.05, 0.2, 0.1, 0.1])
    node = rng.integers(1, 17, n)
    dlc = np.full(n, 8, np.uint8)
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    can_id = np.zeros(n, np.uint32)
    pool = rng.integers(0, 256, (5, 8), dtype=np.uint8)
    pool[0, :2] = 0  # a reset among the repeated payloads
    rep = kind == 0  # EMCY from a pool of payloads
    can_id[rep] = 0x80 + node[rep]
    data[rep] = pool[rng.integers(0, 5, int(rep.sum()))]
    dlc[rep] = rng.choice([8, 8, 8, 5, 3], int(rep.sum()))
    dis = kind == 1  # EMCY, every payload its own, some short
    can_id[dis] = 0x80 + node[dis]
    dlc[dis] = rng.integers(0, 9, int(dis.sum()))
    nmt = kind == 2
    can_id[nmt] = 0
    data[nmt, 0] = rng.choice([1, 2, 0x80, 0x81, 0x82, 0x33], int(nmt.sum()))
    data[nmt, 1] = rng.choice([0, 1, 5, 16], int(nmt.sum()))
    dlc[nmt] = rng.choice([2, 2, 2, 1, 0], int(nmt.sum()))
    boot = kind == 3
    can_id[boot] = 0x700 + node[boot]
    dlc[boot] = 1
    data[boot, 0] = 0
    hb = kind == 4
    can_id[hb] = 0x700 + node[hb]
    dlc[hb] = rng.choice([1, 1, 1, 0], int(hb.sum()))
    data[hb, 0] = rng.choice([5, 5, 5, 0x7F, 4, 0x85, 0x33], int(hb.sum()))
    sync = kind == 5
    can_id[sync] = 0x80
    dlc[sync] = 0
    # SDO expedited uploads, one in three answered by an abort
    req = np.flatnonzero(kind == 6)
    req = req[(req + 1 < n) & (kind[np.minimum(req + 1, n - 1)] != 6)]
    can_id[kind == 6] = 0x180 + node[kind == 6]  # unanswered leftovers: plain TPDOs
    can_id[req] = 0x600 + node[req]
    data[req] = [0x40, 0x00, 0x18, 0x01, 0, 0, 0, 0]
    data[req, 3] = rng.integers(0, 6, req.size)
    resp = req + 1
    can_id[resp] = 0x580 + node[req]
    dlc[resp] = 8
    abort = rng.random(req.size) < 0.33
    data[resp[~abort], 0] = 0x43
    data[resp[abort]] = [0x80, 0x00, 0x18, 0x01, 0x00, 0x00, 0x02, 0x06]
    data[resp, 3] = data[req, 3]
    data[np.arange(8) >= dlc[:, None]] = 0
    fb.can_id[:] = can_id
    fb.dlc[:] = dlc
    fb.data[:] = data
    fb.line[:] = np.arange(1, n + 1)
    return fb


def _decoded(fb: FrameBatch, size: int, **kw):
    decoder = build_decoder(Options(network=kw.get("network"), devices=kw.get("device") or {}))
    for start in range(0, len(fb), size):
        yield decoder.decode(fb.take(slice(start, start + size)))
    yield decoder.finish()


@pytest.mark.parametrize("size", [333, 6000])
def test_generated_emcy_nmt_sdo_events_match_per_row(size):
    count = _assert_same_events(_decoded(_emcy_bus(), size, device=DEVICES))
    assert count > 2000


REAL = [
    "hilch__canopen-message-interpreter/ixxat1.trc",
    "hilch__canopen-message-interpreter/pcan3.trc",
    "RoboTrainerAID__za_experimental/candump.log",
]


@pytest.mark.parametrize("which", REAL)
@pytest.mark.parametrize("size", [997, None])
def test_real_log_events_match_per_row(which, size):
    assert _assert_same_events(decoded_batches(real_file(which), size))


@pytest.mark.parametrize("log", ["faults.log", "commissioning.log", "demo.log"])
def test_sample_events_match_per_row(log):
    kw = {"network": str(SAMPLES / "network.toml")}
    assert _assert_same_events(decoded_batches(SAMPLES / log, 500, **kw))


def test_event_columns_round_trip_and_missing_values():
    rows = [
        Row(2.0, "finding", None, WARNING, "b", None),
        Row(1.0, "sdo", 3, INFO, "a", 7),
        Row(1.0, "custom kind", 0, ERROR, "é", -1),
    ]
    cols = EventColumns.from_rows(rows)
    assert cols.node.tolist() == [NO_NODE, 3, 0] and cols.row.tolist() == [NO_ROW, 7, -1]
    assert cols.rows() == rows
    assert EventColumns.concat([cols, EventColumns.empty(), cols]).rows() == rows + rows
    assert cols.take(np.array([2, 0])).rows() == [rows[2], rows[0]]
    assert cols.sort_key().tolist() == [1 << 62, 7, -1]


def _python_order(batches: list[list[Row]], horizons: list) -> tuple[list[list[str]], bool]:
    """The events table's chunks (messages) as the per-row `_add_events` cut them, and
    whether a chunk started before the previous one ended (a re-sort at the end)."""
    big = 1 << 62
    pending: list[Row] = []
    chunks, last, unsorted = [], None, False
    for batch, horizon in zip(batches, horizons, strict=True):
        pending.extend(batch)
        pending.sort(key=lambda e: (e.t, big if e.row is None else e.row))
        cut = len(pending)
        if horizon is not None:
            cut = bisect.bisect_left([e.t for e in pending], horizon)
        if cut:
            head = (pending[0].t, big if pending[0].row is None else pending[0].row)
            unsorted |= last is not None and head < last
            tail = pending[cut - 1]
            last = (tail.t, big if tail.row is None else tail.row)
            chunks.append([e.message for e in pending[:cut]])
            pending = pending[cut:]
    return chunks, unsorted


class _Chunks:
    def __init__(self) -> None:
        self.chunks: list[list[str]] = []

    def add(self, cols: dict) -> None:
        self.chunks.append(cols["message"].to_pylist())


@pytest.mark.parametrize("nan", [False, True])
@pytest.mark.parametrize("back", [False, True])
def test_pending_events_sorted_and_cut_as_python_does(tmp_path, nan, back):
    """Ties on (t, row) keep arrival order, rows None last, times going back, NaN times."""
    rng = np.random.default_rng(1 + nan + 2 * back)
    batches, horizons = [], []
    for b in range(8):
        rows = []
        for k in range(60):
            t = float(rng.integers(0, 30)) + b * 5 - (40 if back and b == 4 else 0)
            if nan and rng.random() < 0.05:
                t = float("nan")  # a new object each (as times read from columns)
            row = None if rng.random() < 0.2 else int(rng.integers(0, 5))
            kind = rng.choice(["sdo", "emcy", "finding"]).item()
            node = None if rng.random() < 0.3 else int(rng.integers(0, 20))
            rows.append(Row(t, kind, node, INFO, f"b{b} e{k}", row))
        batches.append(rows)
        horizons.append(b * 5 + 20 - HOLD)
    batches[3] = []
    batches.append([])
    horizons.append(None)
    expect, unsorted = _python_order(batches, horizons)
    st = StreamTables(tmp_path / "pq", "parquet")
    st.open()
    sink = _Chunks()
    st.sinks["events"] = sink
    st.writer.put = lambda f: f()
    try:
        for rows, horizon in zip(batches, horizons, strict=True):
            st._add_events(EventColumns.from_rows(rows), horizon)
    finally:
        st.abort()
    assert sink.chunks == expect
    assert st._events_unsorted == unsorted


def test_batch_event_columns_same_as_rows():
    batches = list(_decoded(_emcy_bus(seed=9), 1000, device=DEVICES))
    s1, s2 = EventState(), EventState()
    off = 0
    for batch in batches:
        cols, states = batch_event_columns(batch, off, s1)
        rows, states2 = batch_events(batch, off, s2)
        assert cols.rows() == rows and states == states2
        off += len(batch)
    assert s1.last_t == s2.last_t
    assert {c: v.timeline() for c, v in s1.nmt.items()} == {
        c: v.timeline() for c, v in s2.nmt.items()
    }


@pytest.mark.parametrize("log", ["faults.log", "demo.log"])
def test_finding_events_match_per_row(log):
    """With the rules on, the findings' events (nodes or none, every level) are the
    per-record route's, field by field and type by type."""
    opts = Options(network=str(SAMPLES / "network.toml"), checks=True)
    decoder = build_decoder(opts)
    fb = concat(list(open_log(SAMPLES / log).batches()))
    batches = [decoder.decode(fb.take(slice(s, s + 300))) for s in range(0, len(fb), 300)]
    batches.append(decoder.finish())
    findings = [f for b in batches for f in b.findings]
    assert findings
    assert _assert_same_events(batches) > len(findings)


def test_node_prefix_table_is_the_text_of_each_node() -> None:
    """The "node N: " of the one table of the 128 node-IDs (indexed by node + 1) is the
    text each node's own format gives; nothing for -1, and values off the table as before."""
    from cananalyze.core.columns import bytecols
    from cananalyze.decode.events.build import _node_prefix

    nodes = np.array([-1, *range(128), 5, -1, 127], np.int16)
    want = ["" if k < 0 else f"node {k}: " for k in nodes.tolist()]
    assert bytecols.joined_rows([_node_prefix(nodes)], nodes.size) == want
    odd = np.array([300, 5, -1], np.int16)  # not a node-ID: the per-batch table
    got = bytecols.joined_rows([_node_prefix(odd)], odd.size)
    assert got == ["node 300: ", "node 5: ", ""]
