"""signals.parquet one row per PDO frame, a column per signal (as CSS Electronics' data lakes).

A row is one decoded PDO (or DBC) frame: `t`, `node`, `pdo`, `cob_id`, then one
float64 column per signal, null where that row's PDO does not carry it. One
file holds every PDO of every node: a column is a signal name (several nodes of
one device share it; `node` tells them apart), so a 16-node bus of one device
type has as many columns as that device maps. Each column's field metadata
carries the signal's name and unit (`signal`, `unit`), so the long form
(`load().signals`: one row per value, with `signal` and `unit` columns) is a
view of the file: DuckDB's `UNPIVOT` or a melt gives it back.

Names: a signal is its own column name; one named like a key column is written
`signal:<name>`, and the same name with a second unit gets ` [<unit>]` appended.

Remaps: a PDO whose mapping changes mid-log (SDO writes to 0x1600/0x1A00) brings
its new signals as new columns. The columns are those seen when the first row
group is written (the first 256k rows: every PDO of a steady bus); a signal first
seen later closes the file as a part and the rest goes to a new part with the
wider schema. At the end the parts are merged into one file, the earlier rows
null in the new columns: a rewrite only when a remap brought new signals that late.

Encoding (benchmarks/bench_tables.py): the long form wrote 7 columns per value,
this writes 4 per frame and one per value, in about a third of the time.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np
import pyarrow as pa

from cananalyze.core.columns import arrow_build as ab
from cananalyze.outputs.tables import (
    writer as _writer,  # ROW_GROUP(_BYTES) read at each use: tests set them
)
from cananalyze.outputs.tables.writer import ROW_GROUP, WRITE_BATCH

KEYS = ("t", "node", "pdo", "cob_id")
PDO = pa.dictionary(pa.int32(), pa.string())
BUS = pa.large_string()  # what pandas writes a text column as


class SignalColumns:
    """(signal, unit) -> its column name, in first-seen order (the one naming rule)."""

    def __init__(self) -> None:
        self.names: dict[tuple[str, str], str] = {}

    def column(self, signal: str, unit: str | None) -> str:
        key = (signal, unit or "")
        name = self.names.get(key)
        if name is None:
            base = f"signal:{signal}" if signal in KEYS else signal
            taken = set(self.names.values())
            name = base if base not in taken else f"{base} [{key[1]}]"
            k = 2
            while name in taken:  # same name and unit text twice: cannot happen; kept unique
                name, k = f"{base} #{k}", k + 1
            self.names[key] = name
        return name

    def fields(self) -> list[pa.Field]:
        """The signal columns, each with its signal name and unit in the field metadata."""
        return [
            pa.field(name, pa.float64(), metadata={"signal": s, "unit": u})
            for (s, u), name in self.names.items()
        ]


def schema(columns: SignalColumns, bus: bool = False) -> pa.Schema:
    """The file's columns: the keys, a column per signal, and `bus` last on a log of
    several buses (text, as the events' and the sdo table's)."""
    keys = [
        pa.field("t", pa.float64()),
        pa.field("node", pa.int16()),
        pa.field("pdo", PDO),
        pa.field("cob_id", pa.uint32()),
    ]
    return pa.schema(keys + columns.fields() + ([pa.field("bus", BUS)] if bus else []))


def frame_rows(t_all: np.ndarray, parts: list[tuple], names: SignalColumns) -> dict:
    """One row per (block, frame), sorted by time then series: the columns of a batch.

    `parts`: per signal block (rows, node, pdo code, cob_id, rank, {signal: values},
    units, bus code); `rank` orders series that share a time (as the long form does).
    Returns t, node, pdo codes, cob_id, bus codes, and per signal column (values, valid).
    """
    sizes = [len(p[0]) for p in parts]
    rows = np.concatenate([p[0] for p in parts])
    t = t_all[rows]
    rank = np.repeat(np.array([p[4] for p in parts], np.int32), sizes)
    order = None  # one block in time order: the rows as they are
    if len(parts) > 1 or (len(t) > 1 and not bool((np.diff(t) >= 0).all())):
        order = np.lexsort((rank, t))  # stable: a series' frames of one time in row order
    total = len(rows)
    start = np.cumsum(sizes) - sizes
    inv = np.empty(total, np.int64)  # the position of each unsorted row in the output
    inv[np.arange(total) if order is None else order] = np.arange(total)
    out = {
        "t": t if order is None else t[order],
        "node": np.repeat(np.array([p[1] for p in parts], np.int16), sizes),
        "pdo": np.repeat(np.array([p[2] for p in parts], np.int32), sizes),
        "cob_id": np.repeat(np.array([p[3] for p in parts], np.uint32), sizes),
        "bus": np.repeat(np.array([p[7] for p in parts], np.int32), sizes),
    }
    if order is not None:
        for k in ("node", "pdo", "cob_id", "bus"):
            out[k] = out[k][order]
    signals: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    # new columns in the order their first value comes in the rows (time, then series,
    # then the PDO's mapping): the same order however the log was cut into batches
    first = [
        int(inv[s0 : s0 + n].min()) if n else total for s0, n in zip(start, sizes, strict=True)
    ]
    for k in sorted(range(len(parts)), key=first.__getitem__):
        _, _, _, _, _, cols, units, _ = parts[k]
        where = inv[start[k] : start[k] + sizes[k]]
        for signal, values in cols.items():
            name = names.column(signal, units.get(signal))
            got = signals.get(name)
            if got is None:
                got = signals[name] = (np.zeros(total, np.float64), np.zeros(total, bool))
            got[0][where] = np.asarray(values, np.float64)
            got[1][where] = True
    out["signals"] = signals
    return out


def empty_rows() -> dict:
    """frame_rows' result for no rows."""
    z = np.zeros(0)
    return {
        "t": z,
        "node": z.astype(np.int16),
        "pdo": z.astype(np.int32),
        "cob_id": z.astype(np.uint32),
        "bus": z.astype(np.int32),
        "signals": {},
    }


def arrow_table(
    rows: dict, labels: list[str], sch: pa.Schema, buses: list[str] | None = None
) -> pa.Table:
    """The batch's rows in the file's schema (signals it lacks: null); its `bus`, when
    the schema has one, from the rows' bus codes into `buses` (-1: none, on a log of one
    bus: null)."""
    n = len(rows["t"])
    arrays = [
        ab.numeric(rows["t"]),
        ab.numeric(rows["node"]),
        ab.dictionary(rows["pdo"], ab.strings(labels), pa.int32()),
        ab.numeric(rows["cob_id"]),
    ]
    for f in sch:
        if f.name in KEYS or f.name == "bus":
            continue
        got = rows["signals"].get(f.name)
        arrays.append(pa.nulls(n, pa.float64()) if got is None else ab.numeric(got[0], ~got[1]))
    if "bus" in sch.names:
        code = rows["bus"].astype(np.int64)
        arrays.append(pa.array(buses or [], BUS).take(ab.numeric(code, code < 0)))
    return pa.Table.from_arrays(arrays, schema=sch)


def _options(compression: str) -> dict:
    # statistics on `t` only (the one ordered column: time windows prune row groups);
    # dictionaries on the key columns, whose values repeat, not on the values
    return {
        "compression": compression,
        "use_dictionary": ["node", "pdo", "cob_id"],
        "write_statistics": ["t"],
        "use_byte_stream_split": ["t"],
        "write_batch_size": WRITE_BATCH,
    }


class WideWriter:
    """The wide signals file: row groups as they come, a new part when columns are added."""

    def __init__(self, path: Path, compression: str) -> None:
        self.path = path
        self.compression = compression
        self.names = SignalColumns()
        self.bus = False  # a log of several buses: a bus column (parts before it: the first's)
        self.buses: list[str] = []  # the rows' bus codes index it, the first bus first
        self.buffer: list[tuple[dict, list[str]]] = []
        self.buffered = 0
        self.bytes = 0
        self.rows = 0
        self.writer = None
        self.schema: pa.Schema | None = None
        self.parts: list[Path] = []  # closed parts (a remap brought new columns)

    def add(self, rows: dict, labels: list[str], buses: list[str] | None = None) -> None:
        n = len(rows["t"])
        if buses:
            self.buses = buses  # (a growing list: earlier rows' codes index it too)
        if not n:
            return
        self.buffer.append((rows, labels))
        self.buffered += n
        self.bytes += n * (22 + 9 * len(rows["signals"]))
        if self.buffered >= _writer.ROW_GROUP or self.bytes >= _writer.ROW_GROUP_BYTES:
            self.flush()

    def _options(self) -> dict:
        return _options(self.compression)

    def flush(self) -> None:
        import pyarrow.parquet as pq

        if not self.buffer and self.writer is not None:
            return
        want = schema(self.names, self.bus)
        if self.writer is not None and want != self.schema:
            self.writer.close()  # new signals: this part is done, the rest is wider
            part = self.path.with_name(f"{self.path.name}.part{len(self.parts)}")
            os.replace(self.path, part)
            self.parts.append(part)
            self.writer = None
        if self.writer is None:
            self.schema = want
            self.writer = pq.ParquetWriter(self.path, want, **self._options())
        tables = [arrow_table(rows, labels, want, self.buses) for rows, labels in self.buffer]
        table = pa.concat_tables(tables) if tables else pa.Table.from_batches([], want)
        self.buffer, self.buffered, self.bytes = [], 0, 0
        self.writer.write_table(table, row_group_size=_writer.ROW_GROUP)
        self.rows += table.num_rows

    def close(self) -> None:
        self.flush()
        self.writer.close()
        if self.parts:
            self._merge()

    def _merge(self) -> None:
        """The parts and the last file into one file of the final schema (earlier rows
        null in the columns they lacked), row group by row group."""
        import pyarrow.parquet as pq

        last = self.path.with_name(f"{self.path.name}.part{len(self.parts)}")
        os.replace(self.path, last)
        sources = [*self.parts, last]
        self.parts = sources
        with pq.ParquetWriter(self.path, self.schema, **self._options()) as out:
            for src in sources:
                f = pq.ParquetFile(src)
                for i in range(f.num_row_groups):
                    first = self.buses[0] if self.buses else None
                    out.write_table(conform(f.read_row_group(i), self.schema, first))
                f.close()
        self.discard_parts()

    def discard_parts(self) -> None:
        for p in self.parts:
            with contextlib.suppress(OSError):
                p.unlink()
        self.parts = []

    def discard(self) -> None:
        """Abort: close without the buffered rows; the parts are removed."""
        self.buffer = []
        if self.writer is not None:
            with contextlib.suppress(Exception):
                self.writer.close()
        self.discard_parts()


def resort(path: Path, compression: str) -> None:
    """The finished file's rows by time, then node, PDO, COB-ID (batches that overlapped in
    time: timestamps going back); the whole table in memory, rare."""
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    pdo = table.column("pdo").cast(pa.string()).to_pylist()
    pos = {p: i for i, p in enumerate(sorted({p for p in pdo if p is not None}))}
    code = np.array([pos.get(p, -1) for p in pdo], np.int64)
    order = np.lexsort(
        (
            np.arange(table.num_rows),
            ab.to_numpy(table.column("cob_id")),
            code,
            ab.to_numpy(table.column("node")),
            ab.to_numpy(table.column("t")),
        )
    )
    table = table.take(ab.numeric(np.ascontiguousarray(order, np.int64)))
    tmp = path.with_name(path.name + ".rw")
    try:
        with pq.ParquetWriter(tmp, table.schema, **_options(compression)) as out:
            out.write_table(table, row_group_size=ROW_GROUP)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def conform(table: pa.Table, sch: pa.Schema, first: str | None = None) -> pa.Table:
    """`table` with the columns of `sch` (those it lacks null), in its order; a `bus` it
    lacks is `first` (rows written before a second bus was seen: the first bus's)."""
    n = table.num_rows
    cols = []
    for f in sch:
        if f.name in table.column_names:
            cols.append(table.column(f.name))
        elif f.name == "bus" and first is not None:
            cols.append(pa.array([first] * n, f.type))
        else:
            cols.append(pa.nulls(n, f.type))
    return pa.Table.from_arrays(cols, schema=sch)
