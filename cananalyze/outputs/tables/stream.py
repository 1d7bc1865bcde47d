"""`export --parquet/--csv` as a stream: each DecodedBatch's rows appended to six table files.

`load()`'s Capture keeps every batch, concatenates them and builds pandas
DataFrames (4 GB for 10M frames); this path keeps nothing per frame: frames and
signals go batch by batch to a writer thread (`writer`), SDO records are
spooled to a temporary file (pandas types their columns over the whole column)
and written as they come while the types so far hold, findings are spooled
(`findings_spool`) and written by time at the end, and the nodes table is built
at the end. The files hold the tables of `load(log)`:
`pd.read_parquet` gives its DataFrames back, with their dtypes (mixed-type record
columns as text: Parquet has one type per column); tests read them with pandas.

Row order follows the Capture: signals by time, then series (node, PDO,
COB-ID, first appearance), then signal; events by time, then frame row. Each
batch is sorted on its own; only when a batch starts before the previous one
ended (timestamps going back, or none at all) is the table re-sorted whole at
the end.
"""

from __future__ import annotations

import bisect
import contextlib
import dataclasses
import operator
import pickle
import tempfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pyarrow as pa

from cananalyze.core.atomic import atomic_path
from cananalyze.core.columns import arrow_build as ab
from cananalyze.core.columns.payloads import payload_bytes, payload_hex
from cananalyze.core.errors import UsageError
from cananalyze.core.finding_columns import FindingColumns
from cananalyze.core.frames import FrameBatch
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.events.build import LEVEL_NAMES, EventState, batch_events_of
from cananalyze.decode.events.columns import KINDS, NO_NODE, NO_ROW, EventColumns
from cananalyze.decode.node_load import run_bitrate
from cananalyze.decode.node_tally import NodeTally, bus_profiles, node_profiles
from cananalyze.decode.od_tally import OdTally
from cananalyze.outputs import schemas
from cananalyze.outputs.tables import pandas_like as pl
from cananalyze.outputs.tables import sdo_chunks, wide
from cananalyze.outputs.tables.findings_spool import FindingsSpool
from cananalyze.outputs.tables.writer import (
    DEFAULT_CODEC,
    ROW_GROUP,
    ROW_GROUP_BYTES,
    Coded,
    Sink,
    TableSpec,
    WriterThread,
    csv_schema,
    csv_table,
    rewrite,
)
from cananalyze.pipeline.sink import Sink as OutputSink
from cananalyze.protocol.services import SERVICE_NAMES

TABLES = ("frames", "signals", "sdo", "events", "findings", "nodes")
SDO_COLUMNS = schemas.SDO.without("bus").names
_SDO_ROW = operator.itemgetter(*SDO_COLUMNS)
FINDING_COLUMNS = schemas.FINDINGS.without("bus").names  # as check --json
_NULLABLE_INTS = ("node", "cob_id", "line")  # findings columns of ints or none: Int64
FINDINGS_CHUNK = 8192  # findings rows converted at a time (their values are Python objects)
HOLD = 10.0  # seconds of events kept back for records that complete late (see _add_events)
_NAN = float("nan")  # an absent key: pandas fills NaN, as pandas_like.MISSING
_SERVICES = ab.strings(list(SERVICE_NAMES))
_LEVELS = ab.strings(list(LEVEL_NAMES.values()))


def _meta(fields: list[dict], index: str | None = None):
    return lambda counts: pl.schema_metadata(
        [
            pl.categorical_meta(f["name"], counts.get(f["name"], f["metadata"]))
            if f["pandas_type"] == "categorical"
            else f
            for f in fields
        ],
        index,
    )


def _column_meta(c: schemas.Column) -> dict:
    """pandas' metadata of one declared column (a Coded column's categories counted when
    the file opens, unless fixed)."""
    if c.pandas and c.pandas[0] == "categorical":
        return pl.field_meta(c.name, "categorical", "", c.categories)
    return pl.field_meta(c.name, *c.pandas)


def _pandas_meta(table: schemas.Table) -> list[dict]:
    return [_column_meta(c) for c in table.columns]


_BUS_META = _column_meta(schemas.SDO.column("bus"))  # a text column, as pandas's


def _spec(table: schemas.Table, **writer) -> TableSpec:
    """A table's writer spec: its declared columns, plus how the writer encodes them."""
    return TableSpec(
        table.export_fields(), _meta(_pandas_meta(table)), required=table.required(), **writer
    )


FRAMES = _spec(
    schemas.FRAMES,
    dictionary=("channel", "can_id", "service"),
    split=("t",),
    statistics=("t",),
    uncompressed=("channel", "can_id", "dlc", "data", "flags", "service", "node", "pdo"),
    delta=("dlc", "flags", "node", "pdo"),
)
_SIGNAL_WRITER = dict(
    sorted_labels=("pdo", "signal", "unit"),
    dictionary=("node", "pdo", "cob_id", "signal", "unit"),
    split=("t",),
    statistics=("t",),
)
SIGNALS = _spec(schemas.SIGNALS.without("bus"), **_SIGNAL_WRITER)
# the long form of the signals (CSV, a fleet's parts) of a log of several buses
SIGNALS_BUS = _spec(
    schemas.SIGNALS, **{**_SIGNAL_WRITER, "dictionary": (*_SIGNAL_WRITER["dictionary"], "bus")}
)
_EVENT_WRITER = dict(sorted_labels=("kind",), statistics=("t",))
EVENTS = _spec(schemas.EVENTS.without("bus"), dictionary=("kind", "level", "node"), **_EVENT_WRITER)
# a log of several buses: which one, after the other columns (a fleet's parts always have
# it, null on a log of one bus)
EVENTS_BUS = _spec(schemas.EVENTS, dictionary=("kind", "level", "node", "bus"), **_EVENT_WRITER)


# CSV is text: its `data` column is the payloads' hex, as `decode --format jsonl` writes them
FRAMES_CSV = dataclasses.replace(
    FRAMES, fields=[(n, pa.string() if n == "data" else t) for n, t in FRAMES.fields]
)


def _frames_columns(fb: FrameBatch, service, node, pdo, sync_latency, text: bool = False) -> dict:
    """Built on the writer thread (the payload column is the largest of the frames table);
    `text`: the payloads as hex (CSV), else bytes."""
    channels = list(fb.channels) or ["can0"]
    chan = np.minimum(fb.channel, len(channels) - 1).astype(np.int32)
    return {
        "t": ab.numeric(fb.t),
        "channel": Coded(chan, channels),
        "can_id": ab.numeric(fb.can_id),
        "dlc": ab.numeric(fb.dlc),
        "data": payload_hex(fb) if text else payload_bytes(fb),
        "flags": ab.numeric(fb.flags),
        "service": ab.dictionary(service, _SERVICES, pa.int8()),
        "node": ab.numeric(node.astype(np.int16, copy=False), node < 0),
        "pdo": ab.numeric(pdo.view(np.int8), pdo == 0),
        "sync_latency_ms": pa.nulls(len(fb), pa.float64())
        if sync_latency is None
        else ab.numeric(sync_latency, np.isnan(sync_latency)),
    }


def _outdir(path: str | Path) -> Path:
    """The output folder, created if needed; a one-line UsageError when it cannot be."""
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise UsageError(f"{d}: exists and is not a directory")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"{d}: cannot create the output directory ({exc.strerror})") from None
    return d


class TableSink(OutputSink):
    """The six tables written batch by batch into a folder; the files appear atomically at close.

    `profiles`: node -> (profile, how), for the nodes table when no run says (tests);
    a run's network model names each declared or identified device. `constants`: columns
    of one value appended to every row of frames, signals and events (a fleet's lineage,
    `writer.Sink`). `conform`: for the record tables (types decided per log, as pandas
    would), an object whose `schema(name)` and `table(name, table)` give every chunk the
    dataset's fixed schema as it is written (`fleet/schema`).
    """

    needs_events = True

    def __init__(
        self,
        path: str | Path,
        fmt: str = "parquet",
        compression: str = DEFAULT_CODEC,
        profiles: dict[int, tuple[str, str]] | None = None,
        depth: int = 1,
        constants: dict[str, str] | None = None,
        conform=None,
    ) -> None:
        self.path = path
        self.constants = constants
        self.conform = conform
        self.dest = str(path)
        self.fmt = fmt
        self.compression = compression
        self.profiles = profiles or {}
        self.depth = depth
        self.run = None
        self._stack = None

    def open(self, run=None) -> None:
        """Create the temporary files (the folder must exist or be creatable)."""
        self.run = run
        depth = self.depth
        fmt, compression = self.fmt, self.compression
        self._made_dir = not Path(self.path).exists()  # removed again by abort, if empty
        self.dir = _outdir(self.path)
        self._stack = contextlib.ExitStack()
        self.paths: dict[str, Path] = {}
        for name in self.tables:
            self.paths[name] = self._stack.enter_context(atomic_path(self.dir / f"{name}.{fmt}"))
        # signals.parquet one row per PDO frame, a column per signal (`wide`); CSV and a
        # fleet's dataset parts keep one row per value: a CSV header is fixed at its first
        # line, and every part of a dataset table must share one schema whatever the
        # devices of its log are called
        self.wide = (
            wide.WideWriter(self.paths["signals"], compression)
            if fmt == "parquet" and not self.constants
            else None
        )
        # a dataset part's events always say which bus (one schema for every log)
        self._events_bus = bool(self.constants)  # the events table has a bus column
        self._several = False  # events of several buses seen: the bus column is filled
        self._first_bus: str | None = None  # the first frame's bus (events before the second)
        events = EVENTS_BUS if self._events_bus else EVENTS
        tables = [("frames", FRAMES if fmt == "parquet" else FRAMES_CSV), ("events", events)]
        # a dataset part's signals always say which bus too; a CSV's once a second comes
        self._signals_bus_column = bool(self.constants)
        if self.wide is None:
            tables.insert(1, ("signals", SIGNALS_BUS if self.constants else SIGNALS))
        self.sinks = {
            name: Sink(self.paths[name], fmt, spec, compression, self.constants)
            for name, spec in tables
        }
        # two writer threads: the frames table (most of the Parquet encoding, outside
        # the GIL) runs beside the others, so neither queue holds the decoder back.
        # One job waits per writer: the frames writer is the slowest stage, so a
        # deeper queue is always full and only holds more batches (issue 10: depth 3
        # peaked ~70 MB higher at 10M frames, at the same speed)
        self.frames_writer = WriterThread(depth)
        self.writer = WriterThread(depth)
        self.offset = 0
        self.rows: dict[str, int] = {}
        # signals: series key -> (insertion index, units of its first block)
        self._series: dict[tuple, tuple[int, dict]] = {}
        self._labels = {"pdo": _Vocab(), "signal": _Vocab(), "unit": _Vocab(), "kind": _Vocab()}
        self._labels["bus"] = _Vocab()  # signal blocks' buses, the first bus first
        self._signals_bus = False  # signals of a log of several buses seen: a bus column
        self._signal_last: tuple | None = None
        self._signals_unsorted = False
        self._event_state = EventState()
        self._event_last: tuple | None = None
        self._events_unsorted = False
        self._pending_events = EventColumns.empty()
        self._channels: tuple[str, ...] = ()
        self._nodes = NodeTally()
        self._od = OdTally()
        self._sdo_stats = {c: pl.ColumnStats() for c in SDO_COLUMNS}
        self._sdo_spool = tempfile.TemporaryFile(dir=self.dir, prefix=".sdo-spool.")
        self._sdo_chunks = 0
        # (column decisions, schema, writer) of the sdo file written as chunks come; False: given up
        self._sdo_spec: tuple | bool | None = None
        self._sdo_bus = False  # SDO rows of a log of several buses seen: a bus column
        self._findings = FindingsSpool(self.dir)  # by time at the end, from disk

    def __enter__(self) -> TableSink:
        if self._stack is None:
            self.open()
        return self

    def __exit__(self, typ, exc, tb) -> None:
        if exc is not None:
            self.abort(typ, exc, tb)

    # --- per batch -----------------------------------------------------------------
    def write(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        n = len(fb)
        off = self.offset
        if n:
            if self._first_bus is None:
                self._first_bus = fb.channel_label(int(fb.channel[0]))
            if len(fb.channels) > len(self._channels):
                self._channels = tuple(fb.channels)
            frames = self.sinks["frames"]
            args = (fb, batch.service, batch.node, batch.pdo, batch.sync_latency)
            args += (self.fmt == "csv",)
            self.frames_writer.put(lambda: frames.add(_frames_columns(*args)))
        if batch.signals and self.wide is not None:
            self._add_wide(batch)
        elif batch.signals:
            self._add_signals(batch, off)
        self._add_records(batch)
        self._findings.add(batch.findings)
        events, states = batch_events_of(batch, off, self._event_state)
        self._nodes.add(batch, states, off)
        self._od.add(batch)
        self._add_events(events, float(fb.t[-1]) - HOLD if n else float("-inf"))
        self.offset += n

    def _add_signals(self, batch: DecodedBatch, off: int) -> None:
        t_all = batch.frames.t
        # per part (one signal column of one block): its rows, values and five constants
        v_parts: list[np.ndarray] = []
        consts: dict[str, list[int]] = {k: [] for k in ("node", "cob", "pdo", "sig", "unit")}
        keys: list[tuple] = []  # (node, pdo, cob, insertion) per part: the series order
        col_of: list[int] = []
        rows_of: list[np.ndarray] = []
        consts["bus"] = []
        for blk in batch.signals:
            ins, units, bus = self._series_of(batch, blk)
            pdo_code = self._labels["pdo"].code(blk.pdo)
            bus_code = self._labels["bus"].code(bus)
            for j, (name, values) in enumerate(blk.columns.items()):
                v_parts.append(values)
                consts["bus"].append(bus_code)
                consts["node"].append(blk.node)
                consts["cob"].append(blk.cob_id)
                consts["pdo"].append(pdo_code)
                consts["sig"].append(self._labels["signal"].code(name))
                consts["unit"].append(self._labels["unit"].code(units.get(name) or ""))
                keys.append((blk.node, blk.pdo, blk.cob_id, ins))
                col_of.append(j)
                rows_of.append(blk.rows)
        if not keys:
            return
        labels = {k: self._labels[k].snapshot() for k in ("pdo", "signal", "unit", "bus")}
        sink = self.sinks["signals"]
        if self._signals_bus and not self._signals_bus_column:  # a second bus: say which
            first = self._first_bus
            self.writer.put(lambda: sink.fill_column(SIGNALS_BUS, "bus", first))
            self._signals_bus_column = True
        with_bus, named = self._signals_bus_column, self._signals_bus
        # what the job needs, not the batch: a queued job holding the DecodedBatch kept its
        # frames and records alive too, ~10 MB a batch while this writer was behind
        blocks = [(blk.rows, len(blk.columns)) for blk in batch.signals]

        def columns() -> dict:
            """Ordered and gathered on the writer thread: the numpy work there runs outside the GIL.

            The writer runs batches in order, so the sortedness check against the
            previous batch's last value is made there too (close() reads it after join).
            """
            sizes = [len(r) for r in rows_of]
            row = np.concatenate(rows_of)
            t = t_all[row]
            order = _row_major_order(t_all, blocks, rows_of, col_of, len(t))
            if order is None:
                rank_of = {k: r for r, k in enumerate(sorted(set(keys)))}
                rank = np.repeat(np.array([rank_of[k] for k in keys], np.int32), sizes)
                col = np.repeat(np.array(col_of, np.int32), sizes)
                order = np.lexsort((row, col, rank, t))
            first, last = int(order[0]), int(order[-1])
            part_of = np.repeat(np.arange(len(keys), dtype=np.int32), sizes)[order]
            pf, pl_ = int(part_of[0]), int(part_of[-1])
            head = (float(t[first]), *keys[pf], col_of[pf], int(row[first]) + off)
            tail = (float(t[last]), *keys[pl_], col_of[pl_], int(row[last]) + off)
            if self._signal_last is not None and head < self._signal_last:
                self._signals_unsorted = True
            self._signal_last = tail

            def const(name: str, dtype) -> np.ndarray:
                # a lookup in the parts' small table: one gather from cache, not a
                # repeat over every value and a gather from it
                return np.array(consts[name], dtype)[part_of]

            values = np.concatenate([np.asarray(v, np.float64) for v in v_parts])
            out = {
                "t": t[order],
                "node": const("node", np.int16),
                "pdo": Coded(const("pdo", np.int32), labels["pdo"]),
                "cob_id": const("cob", np.uint32),
                "signal": Coded(const("sig", np.int32), labels["signal"]),
                "value": values[order],
                "unit": Coded(const("unit", np.int32), labels["unit"]),
            }
            if with_bus:  # (a dataset part of a log of one bus: null)
                code = ab.numeric(const("bus", np.int64))
                names = pa.array(labels["bus"], wide.BUS)
                out["bus"] = names.take(code) if named else pa.nulls(len(values), wide.BUS)
            return out

        self.writer.put(lambda: sink.add(columns()))

    def _series_of(self, batch: DecodedBatch, blk) -> tuple[int, dict, str]:
        """(insertion index, units of its first block, bus) of a signal block's series: its
        node, PDO, COB-ID, signal names and bus (the first frame's before a second bus
        was seen: the same series after it), as the Capture keys them."""
        bus = batch.block_bus(blk)
        if bus is not None:
            self._signals_bus = True
        bus = bus or self._first_bus
        skey = (blk.node, blk.pdo, blk.cob_id, tuple(blk.columns), bus)
        got = self._series.get(skey)
        if got is None:
            got = self._series[skey] = (len(self._series), dict(blk.units))
        return (*got, bus)

    def _add_wide(self, batch: DecodedBatch) -> None:
        """The batch's PDO frames as wide rows (`wide.frame_rows`), on the writer thread."""
        parts, keys = [], []
        vocab = self._labels["bus"]
        for blk in batch.signals:
            ins, units, bus = self._series_of(batch, blk)
            keys.append((blk.node, blk.pdo, blk.cob_id, ins))
            code = self._labels["pdo"].code(blk.pdo)
            row = [blk.rows, blk.node, code, blk.cob_id, 0, blk.columns, units, vocab.code(bus)]
            parts.append(row)
        rank_of = {k: r for r, k in enumerate(sorted(set(keys)))}
        for part, k in zip(parts, keys, strict=True):
            part[4] = rank_of[k]
        labels = self._labels["pdo"].snapshot()
        buses, several = vocab.snapshot(), self._signals_bus
        t_all = batch.frames.t
        out = self.wide

        def job() -> None:
            out.bus = several  # (in the writer's order: rows before it have no bus column)
            rows = wide.frame_rows(t_all, [tuple(p) for p in parts], out.names)
            t = rows["t"]
            if len(t):
                head = (float(t[0]), int(rows["node"][0]), labels[rows["pdo"][0]])
                if self._signal_last is not None and head < self._signal_last:
                    self._signals_unsorted = True
                self._signal_last = (float(t[-1]), int(rows["node"][-1]), labels[rows["pdo"][-1]])
            out.add(rows, labels, buses)

        self.writer.put(job)

    def _add_events(self, events: EventColumns, horizon: float | None) -> None:
        """Queue events; write those older than `horizon` (None: all) in (t, row) order.

        Records can complete a batch or two after their time (an SDO answer that
        ends a transfer begun earlier carries the earlier time), so the newest
        HOLD seconds wait for the next batch rather than force a re-sort at the end.
        Pending events stay columns: one lexsort, one searchsorted per batch.
        """
        pending = EventColumns.concat([self._pending_events, events])
        n = len(pending)
        if not n:
            return
        if pending.bus is not None and not self._several:  # the second bus: say which
            self._several = True
            sink, first = self.sinks["events"], self._first_bus
            self.writer.put(lambda: sink.fill_column(EVENTS_BUS, "bus", first))
            self._events_bus = True
        key = pending.sort_key()
        t = pending.t
        if np.isnan(t).any() or (horizon is not None and horizon != horizon):
            order, cut = _event_sort_py(t.tolist(), key.tolist(), horizon)
        else:
            order = np.lexsort((key, t))  # stable: ties stay in the order they came
            cut = n if horizon is None else int(np.searchsorted(t[order], horizon, "left"))
        pending = pending.take(order)
        key = key[order]
        if cut == 0:
            self._pending_events = pending
            return
        events, self._pending_events = pending.take(slice(0, cut)), pending.take(slice(cut, n))
        head = (float(events.t[0]), int(key[0]))
        if self._event_last is not None and head < self._event_last:
            self._events_unsorted = True
        self._event_last = (float(events.t[-1]), int(key[cut - 1]))
        vocab = self._labels["kind"]
        present, first = np.unique(events.kind, return_index=True)
        lut = np.zeros(len(KINDS), np.int32)
        for k in present[np.argsort(first)].tolist():  # new labels in first-seen order
            lut[k] = vocab.code(KINDS[k])
        no_node = events.node == NO_NODE
        no_row = events.row == NO_ROW
        cols = {
            "t": events.t,
            "kind": Coded(lut[events.kind], vocab.snapshot()),
            "node": ab.numeric(np.where(no_node, 0, events.node), no_node, pa.int16()),
            "level": ab.dictionary(events.level - 1, _LEVELS, pa.int8()),
            "message": _message_column(events.message),
            "row": ab.numeric(np.where(no_row, 0, events.row), no_row, pa.int64()),
        }
        if self._events_bus:
            cols["bus"] = self._bus_column(events)
        sink = self.sinks["events"]
        self.writer.put(lambda: sink.add(cols))

    def _bus_column(self, events: EventColumns) -> pa.Array:
        """The events' bus: the first bus's for those built before a second was seen; all
        null on a log of one bus (a dataset part's column)."""
        if not self._several:
            return pa.nulls(len(events), pa.string())
        bus = events.bus
        if bus is None:
            return ab.strings([self._first_bus] * len(events))
        none = np.equal(bus, None)
        if none.any():
            bus = bus.copy()
            bus[none] = self._first_bus
        return ab.strings(bus.tolist())

    def _add_records(self, batch: DecodedBatch) -> None:
        """SDO rows and findings of a batch.

        Every transfer comes as the batch's one record type (`SdoRecords.fields`): the
        columns as they are, the held records (aborted pairs, the tracker's) one by
        one. Here only the column statistics are taken in; merging by record slot,
        spooling and writing (`sdo_chunks`) are numpy work for the writer thread.
        """
        records = batch.records
        if not records:
            return
        fields = records.fields()
        held = sorted(fields.held)
        sdo = [(k, fields.held[k]) for k in held]
        keep = None
        slots = np.arange(len(fields), dtype=np.int64)  # each row's record slot, as merged
        order = None
        if held:
            keep = np.delete(slots, held)
            order = np.argsort(np.concatenate((np.array(held, np.int64), keep)), kind="stable")
        pieces = sdo_chunks.fast_pieces(fields, keep) if len(held) < len(fields) else {}
        bus = None  # a log of several buses: each row's (None: the first bus's)
        if batch.several:
            self._sdo_bus = True
            bus = batch.record_buses(slots)
        rows = []
        for _, r in sdo:  # one C call per record that has every column (nearly all)
            try:
                rows.append(_SDO_ROW(r))
            except KeyError:
                rows.append(tuple(r.get(c, _NAN) for c in SDO_COLUMNS))
        mine = [list(c) for c in zip(*rows, strict=True)] or [[] for _ in SDO_COLUMNS]
        for c, values in zip(SDO_COLUMNS, mine, strict=True):
            sdo_chunks.take_in(self._sdo_stats[c], values, pieces.get(c))
        self._sdo_chunks += 1
        out = self._speculate_sdo()
        spool = self._sdo_spool
        first = self._first_bus

        def chunk() -> None:
            """Spooled (as the pieces: smaller than the merged columns), merged and written
            if the types hold, on the writer thread: numpy and Arrow work."""
            pickle.dump((mine, pieces, order, bus), spool, pickle.HIGHEST_PROTOCOL)
            if out is not None:
                decided, schema, writer, _ = out
                writer.add(_sdo_table(mine, pieces, order, decided, schema, bus, first))

        self.writer.put(chunk)

    # --- the end -----------------------------------------------------------------------
    def close(self) -> dict[str, int]:
        """Write the small tables, wait for the writer, fix order/categories, rename all files.
        Returns the rows per table."""
        rows = self.finish()
        self.commit()
        return rows

    def commit(self) -> None:
        """The finished files replace their targets (pipeline.run: after every sink finished)."""
        self._sdo_spool.close()
        self._findings.close()
        self._stack.close()

    def finish(self) -> dict[str, int]:
        """close() but the rename: every table complete in its temporary file."""
        try:
            self._add_events(EventColumns.empty(), None)
            sdo_done = self._speculate_sdo() is not None  # the types are final now
            if sdo_done:  # the last row group, on the writer thread too
                self.writer.put(self._sdo_spec[2].close)
                self._sdo_spec = False
            for name, sink in self.sinks.items():
                (self.frames_writer if name == "frames" else self.writer).put(sink.close)
            if self.wide is not None:
                self.writer.put(self.wide.close)
            # a file of its own, every finding in hand: written while the writer threads
            # encode their last row groups, not after (0.05 s of a 10M-frame export's wall)
            self.rows["findings"] = self._write_findings()
            self.frames_writer.join()
            self.writer.join()
            self._finish_signals()
            self._finish_events()
            self._finish_frames()
            self.rows.update({name: s.rows for name, s in self.sinks.items()})
            if self.wide is not None:
                self.rows["signals"] = self.wide.rows
            self.rows["sdo"] = self._write_sdo(sdo_done)
            self.rows["nodes"] = self._write_nodes()
            if "od" in self.paths:
                self.rows["od"] = self._write_od()
        except BaseException as exc:
            self.abort(type(exc), exc, exc.__traceback__)
            raise
        return {name: self.rows[name] for name in self.tables}

    def abort(self, typ=None, exc=None, tb=None) -> None:
        """Drop every temporary file (a cut-off export leaves no table behind)."""
        for writer in (self.frames_writer, self.writer):
            with contextlib.suppress(BaseException):
                writer.join()
        if self.wide is not None:
            self.wide.discard()
        if self._sdo_spec:
            with contextlib.suppress(BaseException):
                self._sdo_spec[2].discard()
            self._sdo_spec = False
        self._sdo_spool.close()
        self._findings.close()
        self._stack.__exit__(typ or RuntimeError, exc or RuntimeError("aborted"), tb)
        if self._made_dir:
            with contextlib.suppress(OSError):
                self.dir.rmdir()  # only if empty: nothing of the user's is touched

    def _finish_frames(self) -> None:
        final = list(self._channels) or ["can0"]
        sink = self.sinks["frames"]
        if sink.order.get("channel", final) != final or _type_changed(sink, "channel", final):
            rewrite(sink, {"channel": final})

    def _finish_signals(self) -> None:
        if self.wide is not None:
            if self._signals_unsorted:
                wide.resort(self.paths["signals"], self.compression)
            return
        sink = self.sinks["signals"]
        final = {k: sorted(sink.order.get(k, [])) for k in ("pdo", "signal", "unit")}
        if self._signals_unsorted:
            rewrite(sink, final, self._signal_order)
        elif any(sink.order.get(k, []) != v or _type_changed(sink, k, v) for k, v in final.items()):
            rewrite(sink, final)

    def _signal_order(self, table: pa.Table) -> np.ndarray:
        """The Capture's order again, for a table whose batches overlap in time."""
        rank: dict[tuple, tuple[int, int]] = {}
        named = "bus" in table.column_names and self._signals_bus
        for (node, pdo, cob, names, bus), (ins, _) in self._series.items():
            for j, name in enumerate(names):
                rank.setdefault((node, pdo, cob, name, bus if named else None), (ins, j))
        node = table.column("node").to_pylist()
        pdo = table.column("pdo").to_pylist()
        cob = table.column("cob_id").to_pylist()
        sig = table.column("signal").to_pylist()
        bus = table.column("bus").to_pylist() if named else [None] * len(node)
        rows = list(zip(node, pdo, cob, sig, bus, strict=True))
        series = sorted(sorted(set(rows)), key=lambda k: (k[0], k[1], k[2], *rank.get(k, (0, 0))))
        code_of = {k: i for i, k in enumerate(series)}
        code = np.array([code_of[k] for k in rows], np.int64)
        t = ab.to_numpy(table.column("t"))
        return np.lexsort((np.arange(len(t)), code, t))

    def _finish_events(self) -> None:
        sink = self.sinks["events"]
        final = {"kind": sorted(sink.order.get("kind", []))}
        if self._events_unsorted:
            rewrite(sink, final, _event_order)
        elif sink.order.get("kind", []) != final["kind"] or _type_changed(
            sink, "kind", final["kind"]
        ):
            rewrite(sink, final)

    def _small_table(self, name: str, columns: list[tuple[str, pa.Array, str, str]], index=None):
        meta = pl.schema_metadata([pl.field_meta(c, pt, nt) for c, _, pt, nt in columns], index)
        table = pa.table({c: a for c, a, _, _ in columns}).replace_schema_metadata(meta)
        self._write_small(name, [table], table.schema)
        return table.num_rows

    def _write_small(self, name: str, tables: Iterable[pa.Table], schema: pa.Schema) -> None:
        """Chunks of a record table, in row groups of up to ROW_GROUP rows (as to_parquet)."""
        out = _RecordWriter(self.paths[name], self.fmt, schema, self.compression, self._adapt(name))
        try:
            for table in tables:
                out.add(table)
        except BaseException:
            out.discard()
            raise
        out.close()

    def _adapt(self, name: str):
        """(schema, conform) of a record table written as a dataset part, else None."""
        c = self.conform
        return None if c is None else (c.schema(name), lambda t: c.table(name, t))

    def _sdo_decided(self) -> tuple[tuple[str, str, str], ...]:
        return tuple(self._sdo_stats[c].decide(as_object=c == "value") for c in SDO_COLUMNS)

    def _speculate_sdo(self) -> tuple | None:
        """(decisions, schema, writer) to write the next chunk with now, or None.

        pandas types a column over all of it, so a later chunk can change a type
        (an abort code after none, a text among numbers): then the file written so
        far is dropped and close() writes the table from the spool, as it would
        have anyway. Mostly the first chunk settles the types, the chunks are
        written on the writer thread as they come and close() has only the last
        row group left.
        """
        if self._sdo_spec is False:
            return None
        decided = self._sdo_decided()
        spec = self._sdo_spec
        if spec is not None and (spec[0] != decided or spec[3] != self._sdo_bus):
            self._sdo_spec = False  # (or a second bus: the table gains its bus column)
            self.writer.put(spec[2].discard)
            return None
        if spec is None:
            schema = _sdo_schema(decided, self._sdo_bus)
            out = _RecordWriter(
                self.paths["sdo"], self.fmt, schema, self.compression, self._adapt("sdo")
            )
            spec = self._sdo_spec = (decided, schema, out, self._sdo_bus)
        return spec

    def _write_sdo(self, written: bool) -> int:
        """The sdo table from the spool, unless every chunk was `written` as it came."""
        rows = sum(s.rows for s in self._sdo_stats.values()) // len(SDO_COLUMNS)
        if written:
            return rows
        decided = self._sdo_decided()
        schema = _sdo_schema(decided, self._sdo_bus)
        self._sdo_spool.seek(0)
        first = self._first_bus

        def tables():
            for _ in range(self._sdo_chunks):
                mine, pieces, order, bus = pickle.load(self._sdo_spool)
                yield _sdo_table(mine, pieces, order, decided, schema, bus, first)

        self._write_small("sdo", tables(), schema)
        return rows

    def _write_findings(self) -> int:
        """By time, as load() and `check --json` give them: a rule that judges a span (a
        heartbeat dropout) reports after later findings were emitted.

        Read from the spool and written FINDINGS_CHUNK rows at a time: built whole, the
        Python values of a 10M-frame log's 47k findings peaked 30 MB at the very end of
        the export, above the decode's own peak. pandas types a column over all of it, so
        the chunks are written with the types of the first while the types so far still
        hold (as the sdo table); a later chunk that changes one (a text among numbers)
        makes the table written again with the types of the whole column. On a log of
        several buses, the findings made before the second bus was seen are the first
        bus's (as the events)."""
        spool = self._findings
        n = len(spool)
        starts = range(0, n, FINDINGS_CHUNK)
        names = FINDING_COLUMNS
        if spool.named or self._several:  # several buses: which one
            names = (*FINDING_COLUMNS, "bus")
        stats = {c: pl.ColumnStats() for c in names if c not in _NULLABLE_INTS}
        first = self._first_bus

        def part(i: int) -> FindingColumns:
            return spool.chunk(i, FINDINGS_CHUNK)

        def values_of(rows: FindingColumns, names) -> dict[str, list | np.ndarray]:
            values = _finding_values(rows, names)
            if "bus" in values:
                values["bus"] = [first if b is None else b for b in values["bus"]]
            return values

        def decisions() -> dict[str, tuple[str, str, str]]:
            return {c: s.decide() for c, s in stats.items()}

        out, decided, seen = None, None, 0
        for i in starts:
            rows = part(i)
            values = values_of(rows, stats)
            types = _update(stats, values)
            seen += 1
            if decided is None:
                decided = decisions()
                schema = _findings_schema(decided)
                path, adapt = self.paths["findings"], self._adapt("findings")
                out = _RecordWriter(path, self.fmt, schema, self.compression, adapt)
            elif decisions() != decided:
                out.discard()
                out = None
                break
            out.add(_findings_table(rows, values, types, decided, schema))
        if out is not None:
            out.close()
            return n
        for i in starts[seen:]:  # the types changed: all of the column decides them
            _update(stats, values_of(part(i), stats))
        decided = decisions()
        schema = _findings_schema(decided)

        def tables():
            for i in starts:
                rows = part(i)
                values = values_of(rows, stats)
                types = {c: set(map(type, v)) for c, v in values.items() if type(v) is list}
                yield _findings_table(rows, values, types, decided, schema)

        self._write_small("findings", tables(), schema)
        return n

    @property
    def tables(self) -> tuple[str, ...]:
        """The files written: TABLES, and `od` but in a fleet's dataset parts."""
        return TABLES if self.constants else (*TABLES, "od")

    def _write_od(self) -> int:
        rows = self._od.rows()
        names = list(rows[0]) if rows else list(schemas.OD.without("bus").names)
        out = [(c, *pl.column([r[c] for r in rows])) for c in names]
        return self._small_table("od", out)

    def _write_nodes(self) -> int:
        run = self.run
        if run is None:
            rows = self._nodes.rows(self.profiles)
        else:
            rows = self._nodes.rows(
                node_profiles(run.network), bus_profiles(run.decoder), run_bitrate(run)
            )
        names = list(rows[0]) if rows else ["node"]
        others = [c for c in names if c != "node"]
        # Parquet keeps the index last (to_parquet), CSV first (reset_index)
        names = others + ["node"] if self.fmt == "parquet" else ["node", *others]
        out = [(c, *pl.column([r[c] for r in rows])) for c in names]
        return self._small_table("nodes", out, index="node" if self.fmt == "parquet" else None)


def _sdo_table(
    mine: list,
    pieces: dict,
    order,
    decided: tuple,
    schema: pa.Schema,
    bus: np.ndarray | None = None,
    first: str | None = None,
) -> pa.Table:
    """One chunk of the sdo table: each column merged by record slot and typed as decided;
    with a `bus` column in the schema, each row's `bus` (None, or all of it: `first`)."""
    arrays = [
        sdo_chunks.to_arrow(sdo_chunks.merge(v, pieces.get(c), order), d[0])
        for c, v, d in zip(SDO_COLUMNS, mine, decided, strict=True)
    ]
    if "bus" in schema.names:
        n = len(arrays[0]) if arrays else 0
        names = [first] * n if bus is None else [first if b is None else b for b in bus.tolist()]
        arrays.append(pa.array(names, wide.BUS))
    return pa.Table.from_arrays(arrays, schema=schema)


def _sdo_schema(decided: tuple[tuple[str, str, str], ...], bus: bool = False) -> pa.Schema:
    """The sdo table's schema: each column as decided; `bus` last on a log of several
    buses (as the events and findings)."""
    fields = [pa.field(c, pl.arrow_type(d[0])) for c, d in zip(SDO_COLUMNS, decided, strict=True)]
    metas = [pl.field_meta(c, d[1], d[2]) for c, d in zip(SDO_COLUMNS, decided, strict=True)]
    if bus:
        fields.append(pa.field("bus", wide.BUS))
        metas.append(_BUS_META)
    return pa.schema(fields, metadata=pl.schema_metadata(metas))


def _findings_schema(decided: dict[str, tuple[str, str, str]]) -> pa.Schema:
    """The findings table's schema: each column as decided (as pl.column), the nullable
    ints (node, cob_id, line: none in a log without times) as nullable Int64; `bus`
    (after the others) when it was decided, on a log of several buses."""
    fields, metas = [], []
    for name in (*FINDING_COLUMNS, "bus") if "bus" in decided else FINDING_COLUMNS:
        how, pandas_type, numpy_type = decided.get(name, ("int64", "int64", "Int64"))
        fields.append(pa.field(name, pl.arrow_type(how)))
        metas.append(pl.field_meta(name, pandas_type, numpy_type))
    return pa.schema(fields, metadata=pl.schema_metadata(metas))


def _finding_values(rows: FindingColumns, names) -> dict[str, list | np.ndarray]:
    """A chunk's values of the columns `names`, as `FindingColumns.column` gives them; t
    and t_rel as float64 arrays where they can be (no list of floats to make and read)."""
    times = rows.times()
    values: dict[str, list | np.ndarray] = {}
    for c in names:
        if times is not None and c in ("t", "t_rel"):
            values[c] = times[c == "t_rel"]
        else:
            values[c] = rows.column(c)
    return values


def _update(stats: dict[str, pl.ColumnStats], values: dict) -> dict[str, set[type]]:
    """Each column's statistics take in its values; the types of the lists' values."""
    types = {}
    for c, s in stats.items():
        if type(values[c]) is list:
            types[c] = s.update(values[c])
        else:
            s.update_array(values[c])
    return types


def _findings_table(
    rows: FindingColumns, values: dict, types: dict, decided: dict, schema: pa.Schema
) -> pa.Table:
    """One chunk of the findings table: `values` (per decided column; `types`: those of
    the lists) converted as decided."""
    arrays = []
    for name in schema.names:
        if name in _NULLABLE_INTS:
            ints, missing = rows.ints(name)
            arrays.append(ab.numeric(np.where(missing, 0, ints), missing, pa.int64()))
        else:
            arrays.append(pl.convert(values[name], decided[name][0], types.get(name)))
    return pa.Table.from_arrays(arrays, schema=schema)


def _record_options(schema: pa.Schema) -> dict:
    """A record table's encodings, chosen as the stream tables' (TableSpec): dictionaries
    where values repeat (not on times and measured floats: half the SDO table's write),
    min/max statistics on its times only, the columns a reader filters row groups by."""
    return {
        "use_dictionary": [f.name for f in schema if not pa.types.is_floating(f.type)],
        "write_statistics": [n for n in ("t", "t_start") if n in schema.names],
    }


class _RecordWriter:
    """A record table's file, chunk by chunk, in row groups of up to ROW_GROUP rows (as to_parquet)
    or ROW_GROUP_BYTES, whichever comes first (the cut depends only on the chunks, so a
    table written as it comes and one written again from the spool are the same file)."""

    def __init__(
        self, path: Path, fmt: str, schema: pa.Schema, compression: str, adapt=None
    ) -> None:
        """`adapt`: (schema, function) that every chunk goes through before it is written."""
        if adapt is not None:
            schema, self._adapt = adapt
        else:
            self._adapt = None
        self.schema = schema
        if fmt == "parquet":
            import pyarrow.parquet as pq

            self.writer = pq.ParquetWriter(
                path, schema, compression=compression, **_record_options(schema)
            )
            self._write = lambda t: self.writer.write_table(t, row_group_size=ROW_GROUP)
        else:
            import pyarrow.csv as pacsv

            self.writer = pacsv.CSVWriter(path, csv_schema(schema))
            self._write = lambda t: self.writer.write_table(csv_table(t))
        self.buf: list[pa.Table] = []
        self.rows = 0
        self.bytes = 0
        self.written = False

    def add(self, table: pa.Table) -> None:
        if self._adapt is not None:
            table = self._adapt(table)
        self.buf.append(table)
        self.rows += table.num_rows
        self.bytes += table.nbytes
        if self.rows >= ROW_GROUP or self.bytes >= ROW_GROUP_BYTES:
            self._write(pa.concat_tables(self.buf))
            self.buf, self.rows, self.bytes, self.written = [], 0, 0, True

    def close(self) -> None:
        """The last row group; an empty one only for a table without rows (as to_parquet).
        Built from no batches: `Schema.empty_table` goes through `pa.array`, which imports
        pandas (0.4-0.9 s of a 10M-frame export whose findings filled a row group)."""
        try:
            if self.buf:
                self._write(pa.concat_tables(self.buf))
            elif not self.written:
                self._write(pa.Table.from_batches([], self.schema))
        finally:
            self.writer.close()

    def discard(self) -> None:
        """Close without the last row group (the file is written again or dropped)."""
        self.buf = []
        self.writer.close()


class _Vocab:
    """Labels in first-seen order; codes index into it (a snapshot per chunk)."""

    def __init__(self) -> None:
        self.labels: list[str] = []
        self.index: dict[str, int] = {}
        self._snap: list[str] = []

    def code(self, label: str) -> int:
        i = self.index.get(label)
        if i is None:
            i = self.index[label] = len(self.labels)
            self.labels.append(label)
        return i

    def snapshot(self) -> list[str]:
        if len(self._snap) != len(self.labels):
            self._snap = list(self.labels)
        return self._snap


def _type_changed(sink: Sink, column: str, final: list[str]) -> bool:
    if sink.schema is None or sink.fmt != "parquet":
        return False
    return sink.schema.field(column).type.index_type != pl.code_type(len(final))


def _message_column(message: np.ndarray) -> pa.Array:
    """The events' message column: texts, built as str, so not looked at one by one for
    None (a None among them: a null, as `strings` with nulls makes it)."""
    values = message.tolist()
    try:
        return ab.strings(values, large=True, nulls=False)
    except TypeError:  # not all str: "".join refused them
        return ab.strings(values, large=True)


def _event_sort_py(t: list, key: list, horizon: float | None) -> tuple[list[int], int]:
    """The (t, row) order and cut as Python's sort and bisect give them (times with NaN)."""
    order = sorted(range(len(t)), key=lambda i: (t[i], key[i]))
    if horizon is None:
        return order, len(t)
    return order, bisect.bisect_left([t[i] for i in order], horizon)


_LAST_ROW = np.iinfo(np.int64).max  # an event without a frame row sorts after those with one


def _event_order(table: pa.Table) -> np.ndarray:
    """Events by time, then frame row, ties in file order (the Capture's stable sort)."""
    t = ab.to_numpy(table.column("t"))
    row = ab.to_numpy(table.column("row"), fill=_LAST_ROW)
    return np.lexsort((np.arange(len(t)), row, t))


def _row_major_order(
    t: np.ndarray,
    blocks: list[tuple[np.ndarray, int]],
    rows_of: list[np.ndarray],
    col_of: list[int],
    total: int,
) -> np.ndarray | None:
    """The signals' (t, series, column, row) order without a sort, when times allow it.

    When the frames that carry signals have strictly increasing times and each
    belongs to one PDO block, that order is simply frame by frame, each frame's
    values in column order: positions follow from a running count. Otherwise
    (equal or backward times, e.g. millisecond logs) None, and the caller sorts.
    A four-key lexsort over every value was a tenth of the export's main thread.
    `t`: the batch's frame times; `blocks`: (rows, column count) of each signal block.
    """
    n = len(t)
    width = np.zeros(n, np.int64)
    for rows, columns in blocks:
        width[rows] = columns
    carrying = np.flatnonzero(width)
    if sum(len(rows) for rows, _ in blocks) != carrying.size:  # a frame in two blocks
        return None
    if carrying.size > 1 and not bool((np.diff(t[carrying]) > 0).all()):
        return None
    start = np.cumsum(width) - width
    pos = np.concatenate([start[rows] + j for rows, j in zip(rows_of, col_of, strict=True)])
    if pos.size != total:
        return None
    order = np.empty(total, np.int64)
    order[pos] = np.arange(total)
    return order
