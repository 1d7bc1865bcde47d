"""`report` / `check --html`: one self-contained HTML page built from the decoded batches.

The sink reads the same columns as every other output (frames, SDO records,
signals, findings, events and NMT states) and keeps only bounded summaries
(`accum`): statistics over every frame, plotted series decimated to a pixel's
min and max. At close it lays the page out (`page.render`) and writes it atomically.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cananalyze.checks.streamstats import StreamStats
from cananalyze.core.atomic import Staged, check_writable
from cananalyze.core.finding import Finding
from cananalyze.decode.drive_tracker import STATE
from cananalyze.decode.events.columns import EMCY
from cananalyze.decode.node_tally import NodeTally
from cananalyze.outputs.report.accum import Envelope, WindowSums
from cananalyze.pipeline.sink import Sink
from cananalyze.protocol.busload import frame_bits
from cananalyze.protocol.services import Service

MAX_STATES = 20_000  # NMT state changes kept for the timelines (a reset loop makes many)
MAX_LISTED = 500  # SDO aborts listed one by one; counted beyond
# EMCY frames kept for the EMCY table, counted beyond: a reset (code 0) ends an error's
# row instead of making one, so a node raising and clearing gives about half as many rows
MAX_EMCY_FRAMES = 4 * MAX_LISTED
MAX_SERIES = 256  # signals plotted (one envelope each)


@dataclass
class Gaps:
    """Intervals between one key's frames (a node's heartbeats, a COB-ID's PDOs)."""

    last: float | None = None
    count: int = 0
    first_t: float | None = None
    last_t: float | None = None
    # the statistics `--summary` and `--timing` compute (one computation, issue 44 item 1)
    hist: StreamStats = field(default_factory=StreamStats)
    over_time: Envelope = field(default_factory=Envelope)

    def add(self, t: np.ndarray) -> None:
        if t.size == 0:
            return
        if self.first_t is None:
            self.first_t = float(t[0])
        prev = np.concatenate(([self.last], t[:-1])) if self.last is not None else t[:-1]
        at = t if self.last is not None else t[1:]
        gaps = (at - prev) * 1000.0
        self.hist.add(gaps[np.isfinite(gaps)])
        self.over_time.add(at, gaps)
        self.last = self.last_t = float(t[-1])
        self.count += t.size


@dataclass
class Bus:
    """One channel's frames, error frames and load."""

    frames: int = 0
    errors: int = 0
    load: WindowSums = field(default_factory=WindowSums)


@dataclass
class Series:
    node: int
    pdo: str
    cob_id: int
    name: str
    unit: str | None
    env: Envelope = field(default_factory=Envelope)
    # integer and boolean values (digital inputs, states, counters) are drawn as steps:
    # a line between two samples would show values the signal never had
    stepped: bool = True


def _bus_of(fb, row: int) -> str:
    """The name of the channel of the batch's row `row` ("" outside the batch)."""
    return fb.channel_label(int(fb.channel[row])) if 0 <= row < len(fb) else ""


def _record_buses(batch, slots: np.ndarray) -> np.ndarray:
    """The bus of each record slot (`DecodedBatch.record_buses`), "" where it has none: a
    log of one bus, or a record made before a second bus was seen."""
    out = batch.record_buses(slots)
    out[np.equal(out, None)] = ""
    return out


def _groups(keys: np.ndarray):
    """(key, positions in original order) per distinct key (one stable sort)."""
    if keys.size == 0:
        return
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    cut = np.flatnonzero(ks[1:] != ks[:-1]) + 1
    for a, b in zip(np.r_[0, cut].tolist(), np.r_[cut, ks.size].tolist(), strict=True):
        yield int(ks[a]), order[a:b]


class ReportSink(Sink):
    """Collects bounded summaries of the run; writes the page at close."""

    needs_events = True

    def __init__(
        self,
        path: str | Path,
        bitrate: int | None = None,
        title: str | None = None,
        differences=None,
    ):
        self.path = Path(path)
        self.bitrate = bitrate
        self.title = title
        # `report --against B`: the api's Comparison (differences with `cells`, a note),
        # made before this run; None: no Differences section
        self.differences = differences
        self._staged: Staged | None = None  # the page, written at finish, in place at commit
        self.findings: list[Finding] = []
        self.tally = NodeTally()
        # each keyed by its bus too (the channel's name): node 5 on can0 and on can1 are
        # two devices; the page names the bus only when the log has more than one
        self.states: list[tuple[float, tuple[str, int], str]] = []  # t, (bus, node), state
        self.states_dropped = 0
        self.drive_states: list[tuple[float, tuple[str, int], str]] = []  # as states
        # ("heartbeat"|"guarding", node), and the bus's name once there are several
        self.errctl: dict[tuple, Gaps] = {}
        self.pdos: dict[tuple[str, int], Gaps] = {}  # (bus, COB-ID) -> gaps
        self.pdo_node: dict[tuple[str, int], tuple[int, str]] = {}
        # SDO transfers by (bus, node): bus "" until the decoder split by bus (then
        # the first bus's, `first_bus`), a channel's name after
        self.sdo_latency: dict[tuple[str, int], StreamStats] = {}
        self.sdo_count: dict[tuple[str, int], list[int]] = {}  # -> [ok, abort]
        self.aborts: list[tuple[str, dict]] = []  # (bus, record)
        # t, line, bus, node, code, reg, text; the line orders a log without times
        self.emcys: list[tuple[float, int, str, int, int, int, str]] = []
        self.emcy_count = 0
        self.bootups: list[tuple[float, int, str, int]] = []  # t, line, bus, node
        self.buses: dict[str, Bus] = {}
        self.series: dict[tuple, Series] = {}
        self.series_dropped = 0
        self.frames = 0
        self.t_first: float | None = None
        self.line_last = 0  # the last frame's line (the x axis of a log without times)
        self.t_last: float | None = None

    @property
    def several(self) -> bool:
        """More than one bus: the page names each node's bus ("can1 node 5")."""
        return len(self.buses) > 1

    @property
    def timed(self) -> bool:
        """False for a log without times (candump's screen output): every frame has one
        time, so the report orders and places things by line."""
        checker = self.run.checker
        if checker is not None and checker.timed is not None:
            return bool(checker.timed)
        return not (self.frames > 1 and self.t_first == self.t_last)

    def who(self, bus: str, node: int) -> str:
        """ "node 5", or "can1 node 5" on a log of several buses."""
        return f"{bus} node {node}" if self.several and bus else f"node {node}"

    def first_bus(self, bus: str) -> str:
        """`bus`, or the log's first bus for "" (what was seen before a second bus)."""
        return bus or next(iter(self.buses), "")

    def network_of(self, bus: str | None):
        """The network model that bus's decoder kept (each bus decodes on its own)."""
        run = self.run
        if run is None:
            return None
        return run.decoder.of_bus(bus).network if bus else run.network

    def open(self, run) -> None:
        super().open(run)
        check_writable(self.path)

    # --- per batch ------------------------------------------------------------------
    def write(self, batch) -> None:
        fb = batch.frames
        self.findings.extend(batch.findings)
        off = self.run.rows if self.run else 0  # the states' row of the batch's first frame
        self.tally.add(batch, batch.states, off)
        timed = self.timed  # a log without times places states and signals by line
        for s in batch.states:
            if len(self.states) < MAX_STATES:
                at = s.t if timed else self._line(fb, s.row - off, s.t)
                self.states.append((at, (_bus_of(fb, s.row - off), s.node), s.message))
            else:
                self.states_dropped += 1
        self._sdo(batch)
        self._drive_states(batch, timed)
        n = len(fb)
        if not n:
            return
        self.frames += n
        self.line_last = max(self.line_last, int(fb.line.max()))
        t = fb.t
        lo, hi = float(t.min()), float(t.max())
        self.t_first = lo if self.t_first is None else min(self.t_first, lo)
        self.t_last = hi if self.t_last is None else max(self.t_last, hi)
        self._buses(fb)
        service, node = batch.service, batch.node
        for kind, svc in (("heartbeat", Service.HEARTBEAT), ("guarding", Service.GUARD_RESPONSE)):
            rows = np.flatnonzero(service == svc)
            if len(self.buses) > 1:  # several buses: node 5 on each its own gaps
                key = node[rows].astype(np.int64) | (fb.channel[rows].astype(np.int64) << 8)
                for k, pos in _groups(key):
                    at = (kind, k & 0xFF, fb.channel_label(k >> 8))
                    self.errctl.setdefault(at, Gaps()).add(t[rows[pos]])
                continue
            for nd, pos in _groups(node[rows]):
                self.errctl.setdefault((kind, nd), Gaps()).add(t[rows[pos]])
        boot = np.flatnonzero(service == Service.BOOTUP)
        buses = [_bus_of(fb, r) for r in boot.tolist()]
        self.bootups.extend(
            zip(t[boot].tolist(), fb.line[boot].tolist(), buses, node[boot].tolist(), strict=True)
        )
        pdo_rows = np.flatnonzero(batch.pdo > 0)
        key = fb.can_id[pdo_rows].astype(np.int64) | (fb.channel[pdo_rows].astype(np.int64) << 16)
        for k, pos in _groups(key):
            r = pdo_rows[pos]
            at = (fb.channel_label(k >> 16), k & 0xFFFF)  # (bus, COB-ID)
            self.pdos.setdefault(at, Gaps()).add(t[r])
            if at not in self.pdo_node:
                tx = service[r[0]] == Service.TPDO
                self.pdo_node[at] = (
                    int(node[r[0]]),
                    f"{'t' if tx else 'r'}pdo{int(batch.pdo[r[0]])}",
                )
        self._emcy(batch)
        for sb in batch.signals:
            ts = t[sb.rows] if timed else fb.line[sb.rows].astype(np.float64)
            bus = _bus_of(fb, int(sb.rows[0])) if len(sb.rows) else ""  # a block: one bus's
            for name, values in sb.columns.items():
                key = (bus, sb.node, sb.pdo, sb.cob_id, name)
                s = self.series.get(key)
                if s is None:
                    if len(self.series) >= MAX_SERIES or values.dtype == object:
                        self.series_dropped += key not in self.series
                        continue
                    s = self.series[key] = Series(
                        sb.node, sb.pdo, sb.cob_id, name, sb.units.get(name)
                    )
                if values.dtype.kind not in "iub":
                    s.stepped = False
                s.env.add(ts, values.astype(np.float64))

    def _buses(self, fb) -> None:
        bits = frame_bits(fb.flags, fb.dlc).astype(np.float64)
        err = (fb.flags & 4) != 0  # FLAG_ERR
        for ch, pos in _groups(fb.channel.astype(np.int64)):
            bus = self.buses.setdefault(fb.channel_label(ch), Bus())
            bus.frames += pos.size
            bus.errors += int(err[pos].sum())
            bus.load.add(fb.t[pos], bits[pos])
        if len(self.buses) > 1 and self.errctl and len(next(iter(self.errctl))) == 2:
            first = next(iter(self.buses))  # a second bus: the gaps so far are the first's
            self.errctl = {(kind, nd, first): g for (kind, nd), g in self.errctl.items()}

    def _sdo(self, batch) -> None:
        if not batch.records:
            return
        table = batch.records.table()
        buses = _record_buses(batch, table.slots)
        codes = table.node
        if len(set(buses.tolist())) > 1:  # (bus, node) pairs
            names, bus_code = np.unique(buses.astype(str), return_inverse=True)
            codes = codes * len(names) + bus_code.reshape(-1)
        for _, pos in table.groups(codes):
            nd = table.node_keys[table.node[pos[0]]]
            if nd is None:
                continue
            key = (buses[pos[0]], nd)
            lat = table.latency[pos]
            self.sdo_latency.setdefault(key, StreamStats()).add(lat[np.isfinite(lat)])
            res = table.result[pos]
            ok_code = table.result_keys.index("ok") if "ok" in table.result_keys else -1
            ok = int((res == ok_code).sum())
            c = self.sdo_count.setdefault(key, [0, 0])
            c[0] += ok
            c[1] += pos.size - ok
        if len(self.aborts) >= MAX_LISTED:
            return
        recs = batch.records
        at = np.flatnonzero(~recs.cols.ok).tolist()
        found = [(k, recs.record(k)) for k in at]
        found.sort(key=lambda kr: kr[1].get("t") or 0.0)
        found = found[: MAX_LISTED - len(self.aborts)]
        at = _record_buses(batch, np.array([k for k, _ in found], np.int64))
        self.aborts.extend(zip(at.tolist(), [r for _, r in found], strict=True))

    def _drive_states(self, batch, timed: bool) -> None:
        """CiA 402 drive states, drawn as the NMT lanes: a lane per bus and node (node 1
        on can0 and node 1 on can1 are two drives), a bar per state entered."""
        fb = batch.frames
        for c in batch.drive:
            if c.kind != STATE:
                continue
            if len(self.drive_states) >= MAX_STATES:
                break
            at = c.t if timed else self._line(fb, c.row, c.t)
            self.drive_states.append((at, (_bus_of(fb, c.row), c.node), c.name))

    @staticmethod
    def _line(fb, row: int, default: float) -> float:
        """The file line of the batch's row `row` (where a log without times places it)."""
        return float(fb.line[row]) if 0 <= row < len(fb) else default

    def axis(self) -> tuple[float, float, str]:
        """(first, last, title) of the plots' x axis: seconds from the first frame, or on a
        log without times the file's lines (every frame has one time: no time axis)."""
        if self.timed:
            return self.t0, self.t_last or self.t0, "time (s)"
        return 0.0, float(self.line_last + 1), "line"

    def _emcy(self, batch) -> None:
        fb = batch.frames
        rows = np.flatnonzero(batch.service == Service.EMCY)
        if rows.size == 0:
            return
        self.emcy_count += rows.size
        texts: dict[int, str] = {}  # by the frame's row: a log without times has one t
        ev = batch.events
        if ev is not None and len(ev):
            at = np.flatnonzero(ev.kind == EMCY)
            for row, msg in zip(ev.row[at].tolist(), ev.message[at], strict=True):
                texts[row] = msg
        for r in rows[: max(MAX_EMCY_FRAMES - len(self.emcys), 0)].tolist():
            d = fb.data[r]
            code = int(d[0]) | int(d[1]) << 8 if fb.dlc[r] >= 2 else -1
            reg = int(d[2]) if fb.dlc[r] >= 3 else -1
            tt, nd, line = float(fb.t[r]), int(batch.node[r]), int(fb.line[r])
            self.emcys.append((tt, line, _bus_of(fb, r), nd, code, reg, texts.get(r, "")))

    # --- the end --------------------------------------------------------------------
    def close(self) -> None:
        self.finish()
        self.commit()

    def finish(self) -> None:
        """The page rendered and written beside its target; in place at `commit`."""
        from cananalyze.outputs.report.page import render

        for bus in self.buses.values():
            bus.load.finish()
        self.findings.sort(key=lambda f: f.t)
        self._staged = Staged(self.path)
        self._staged.write_text(render(self))

    def commit(self) -> None:
        if self._staged is not None:
            self._staged.commit()
            self._staged = None

    def abort(self) -> None:
        if self._staged is not None:
            self._staged.abort()
            self._staged = None
