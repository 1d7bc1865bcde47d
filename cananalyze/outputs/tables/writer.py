"""Table files written on the other core: Arrow chunks go through a bounded queue to a writer thread.

pyarrow's Parquet and CSV writers release the GIL, so while the main thread
decodes batch k+1 the writer thread builds and encodes batch k. The queue is
bounded (`depth` chunks), so memory does not grow when the disk is slower than
the decoder. Each table is written to its temporary file (`atomic.atomic_path`)
in row groups of `ROW_GROUP` rows; `finish` renames them only when everything
succeeded.

Dictionary columns whose categories are known only at the end (signal names,
event kinds) arrive as `Coded` (codes into a growing label list). The sink
fixes the file's category order at its first row group (sorted, as
`pd.Categorical` sorts them) and appends later labels; when the final order
differs from what pandas would give, or rows must be re-sorted, `finish`
rewrites the file from its own row groups.
"""

from __future__ import annotations

import contextlib
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa

# Imported here, before any writer thread starts: since Arrow 21 importing
# pyarrow._compute registers the compute kernels in the global registry, and doing
# that on one writer thread while another's Parquet writer looks a kernel up fails
# at random ("No function registered with name: unique"). Only the kernels: the
# pyarrow.compute module (which imports this too) also builds a Python wrapper
# per kernel, ~60 ms of CPU that an export whose tables need no pc.* call saves.
# pyarrow._compute is private: a pyarrow without it gets the public module.
try:
    import pyarrow._compute  # noqa: F401
except ImportError:  # pragma: no cover - pyarrow's layout changed
    import pyarrow.compute  # noqa: F401

from cananalyze.core.columns import arrow_build as ab
from cananalyze.outputs.tables.pandas_like import code_type

# Rows per row group: 256k (pyarrow's default is 1M) lets the writer start while the
# decoder is still at the first quarter of a 1M-frame log, and bounds what waits in memory.
ROW_GROUP = 1 << 18
# ... and at most this many bytes wait for a row group. Wide, sparse tables (events,
# SDO rows: 100-180 bytes a row, a few thousand rows a batch) would otherwise hold
# tens of megabytes over dozens of batches before their first write, so a 10M-frame
# log peaked 40-70 MB higher than a 5M one, which never filled a row group at all.
# 4 MiB (25-40k event rows): at 16 MiB, turning a buffer into a row group (Arrow
# table, then Parquet pages) was a 30-50 MB spike, and a long log met more of them
# at moments the writer queues were full; at 4 MiB a 50M-frame export peaks ~100 MB
# lower than at 16 MiB, for the same time.
ROW_GROUP_BYTES = 4 << 20
# Rows the Parquet encoders take per call (Arrow's default is 1024): 16k makes the
# frames and signals tables 5 % quicker to encode, with the same pages and file.
WRITE_BATCH = 1 << 14
DEFAULT_CODEC = "snappy"  # as pandas writes Parquet; --parquet-compression picks another


def nbytes(value) -> int:
    """Bytes of one buffered column: a numpy array, an Arrow array or a `Coded`."""
    if isinstance(value, Coded):
        return value.codes.nbytes
    return value.nbytes


@dataclass
class Coded:
    """A dictionary column: codes into `labels` (a snapshot of a growing label list)."""

    codes: np.ndarray
    labels: list[str]


@dataclass
class TableSpec:
    """A table's columns and their Arrow types; Coded columns get their index type at open."""

    fields: list[tuple[str, pa.DataType | None]]  # None: a Coded column (dictionary of strings)
    metadata: Callable[[dict[str, int]], dict[bytes, bytes]]  # categories per Coded column -> meta
    sorted_labels: tuple[str, ...] = ()  # Coded columns whose categories pandas sorts
    # Parquet dictionary encoding only where values repeat: trying it on times and
    # payloads costs 25 % of the write and makes the file larger
    dictionary: tuple[str, ...] | bool = True
    # BYTE_STREAM_SPLIT for float columns whose bytes vary at the bottom (times): the
    # frames table's `t` encodes in half the time and is a third smaller than PLAIN
    split: tuple[str, ...] = ()
    # min/max statistics only where a reader prunes row groups with them: DuckDB and
    # pyarrow.dataset skip a row group by the min/max of a filtered column, and only
    # time is ordered in these tables (a row group holds every node, COB-ID and
    # service of its quarter-second, so their ranges prune nothing); computing them
    # on every column was a tenth of the frames table's encoding (bench_tables.py)
    statistics: tuple[str, ...] | bool = True
    # columns that are never null, declared non-nullable: Parquet writes them REQUIRED,
    # without definition levels (their RLE encoding was a tenth of the frames table's
    # encoding). Readers see the same types and values (pandas: the same dtypes; the
    # Arrow schema read back says `not null`). Not in a fleet's dataset parts, whose
    # one schema per table (fleet/schema) is nullable throughout.
    required: tuple[str, ...] = ()
    # columns the default codec (snappy, chosen for speed) leaves uncompressed, where it
    # costs more than it saves: ~0.17 s CPU per 10M frames on the frames table's payloads
    # (5 % of the whole export) for 17 % smaller payloads (near random bytes), almost
    # nothing saved on dictionary-coded small integers. A codec the user asks for
    # (--parquet-compression zstd: for size) compresses every column.
    uncompressed: tuple[str, ...] = ()
    # DELTA_BINARY_PACKED for small integer columns instead of a dictionary: hashing
    # every value into a dictionary was the frames table's costliest encoding (~0.1 s
    # CPU per 10M frames more for dlc, flags, node and pdo, for 4 % less file)
    delta: tuple[str, ...] = ()

    def compression(self, names: list[str], codec: str) -> str | dict[str, str]:
        """ParquetWriter's `compression`: snappy for every column but `uncompressed`;
        another codec for every column."""
        if not self.uncompressed or codec.lower() != DEFAULT_CODEC:
            return codec
        return {n: "none" if n in self.uncompressed else codec for n in names}

    def parquet_options(self) -> dict:
        """The ParquetWriter keywords of this table's column encodings."""
        d, s = self.dictionary, self.statistics
        opts = {
            "use_dictionary": list(d) if d is not True else True,
            "use_byte_stream_split": list(self.split) if self.split else False,
            "write_statistics": list(s) if s is not True else True,
            "write_batch_size": WRITE_BATCH,
        }
        if self.delta:  # pyarrow takes per-column encodings in one keyword or the other
            assert d is not True and not set(d) & set(self.delta), "dictionary or delta"
            del opts["use_byte_stream_split"]
            opts["column_encoding"] = {
                **dict.fromkeys(self.split, "BYTE_STREAM_SPLIT"),
                **dict.fromkeys(self.delta, "DELTA_BINARY_PACKED"),
            }
        return opts


# The one label type of a dataset's parts (`constants` given): every file of a table must
# agree, whatever number of categories one log has (pandas' width: `code_type`)
LABEL = pa.dictionary(pa.int32(), pa.string())


class Sink:
    """One table file: buffered chunks, written as row groups (Parquet) or CSV lines.

    `constants`: columns of one value each, appended to every row (a fleet's lineage:
    source, hash, version); with them, dictionary columns are `LABEL` in every file and
    the file carries no pandas metadata (it is a dataset part, not `load()`'s table).
    """

    def __init__(
        self,
        path: Path,
        fmt: str,
        spec: TableSpec,
        compression: str,
        constants: dict[str, str] | None = None,
    ) -> None:
        self.path = path
        self.fmt = fmt
        self.spec = spec
        self.compression = compression
        self.constants = dict(constants or {})
        self.fields = list(spec.fields) + [(c, None) for c in self.constants]
        self.buffer: list[dict] = []
        self.buffered = 0
        self.buffered_bytes = 0
        self.rows = 0
        self.writer = None
        self.schema: pa.Schema | None = None
        self.order: dict[str, list[str]] = {}  # Coded column -> categories in file order
        self.pos: dict[str, dict[str, int]] = {}

    def add(self, columns: dict) -> None:
        n = len(next(iter(columns.values()))) if columns else 0
        if n == 0:
            return
        if self.constants:
            zeros = np.zeros(n, np.int32)
            columns = {**columns, **{c: Coded(zeros, [v]) for c, v in self.constants.items()}}
        self.buffer.append(columns)
        self.buffered += n
        self.buffered_bytes += sum(nbytes(v) for v in columns.values())
        if self.buffered >= ROW_GROUP or self.buffered_bytes >= ROW_GROUP_BYTES:
            self.flush()

    def fill_column(self, spec: TableSpec, name: str, value: str) -> None:
        """Every row so far, buffered or written, gets `value` in column `name` (of `spec`,
        the table with that column; added if this one lacks it). For a log whose second
        bus comes after events were written: the file is read back and written again
        (rare: a row group of events before it)."""
        typ = dict(spec.fields)[name]
        self.spec = spec
        self.fields = list(spec.fields) + [(c, None) for c in self.constants]
        for cols in self.buffer:
            cols[name] = pa.array([value] * len(cols["t"]), typ)
        if self.writer is None:
            return
        self.writer.close()
        self.writer = None
        old = self.schema
        table = _read_back(self, old)
        table = table.drop_columns([name]) if name in table.column_names else table
        table = table.append_column(name, pa.array([value] * table.num_rows, typ))
        fields = [old.field(n) if n in old.names else pa.field(n, typ) for n, _ in self.fields]
        counts = {k: len(v) for k, v in self.order.items()}
        self.schema = pa.schema(fields, metadata=self.metadata(counts))
        target = self.schema if self.fmt == "parquet" else csv_schema(self.schema)
        self.rows = 0
        self._write(pa.Table.from_arrays([table.column(f.name) for f in target], schema=target))

    def _extend_order(self) -> None:
        for name, typ in self.fields:
            if typ is not None:
                continue
            order = self.order.setdefault(name, [])
            pos = self.pos.setdefault(name, {})
            new: dict[str, None] = {}
            for cols in self.buffer:
                for label in cols[name].labels:
                    if label not in pos and label not in new:
                        new[label] = None
            labels = sorted(new) if name in self.spec.sorted_labels else list(new)
            for label in labels:
                pos[label] = len(order)
                order.append(label)

    def flush(self) -> None:
        if not self.buffer and self.writer is not None:
            return
        self._extend_order()
        if self.schema is None:
            self.schema = self._schema()
        batches = [self._batch(cols) for cols in self.buffer]
        self.buffer, self.buffered, self.buffered_bytes = [], 0, 0
        table = pa.Table.from_batches(batches, self.schema)
        self._write(table)

    def _schema(self) -> pa.Schema:
        fields = []
        for name, typ in self.fields:
            if typ is None and self.constants:
                typ = LABEL
            elif typ is None:  # no categories at all: pandas' empty Categorical has null values
                values = pa.string() if self.order[name] else pa.null()
                typ = pa.dictionary(code_type(len(self.order[name])), values)
            # a column of no categories is of null values (no frames at all): nullable
            values = typ.value_type if pa.types.is_dictionary(typ) else typ
            required = name in self.spec.required and not self.constants
            fields.append(pa.field(name, typ, nullable=not required or pa.types.is_null(values)))
        return pa.schema(fields, metadata=self.metadata({k: len(v) for k, v in self.order.items()}))

    def metadata(self, counts: dict[str, int]) -> dict | None:
        return None if self.constants else self.spec.metadata(counts)

    def parquet_options(self) -> dict:
        opts = self.spec.parquet_options()
        # a dataset part's lineage (source, hash, version) is one value per file: its
        # statistics let DuckDB skip whole files of other logs (`WHERE source = ...`)
        for key in ("use_dictionary", "write_statistics"):
            if self.constants and opts[key] is not True:
                opts[key] = [*opts[key], *self.constants]
        return opts

    def _batch(self, cols: dict) -> pa.RecordBatch:
        arrays = []
        for f in self.schema:
            value = cols[f.name]
            if isinstance(value, Coded):
                pos = self.pos[f.name]
                remap = np.array([pos[label] for label in value.labels], np.int32)
                idx = remap[value.codes] if remap.size else np.zeros(0, np.int32)
                labels = self.order[f.name]
                labels = ab.strings(labels) if labels or self.constants else pa.nulls(0)
                value = ab.dictionary(idx, labels, f.type.index_type)
            elif not isinstance(value, (pa.Array, pa.ChunkedArray)):
                value = ab.numeric(value, typ=f.type)
            arrays.append(value)
        return pa.RecordBatch.from_arrays(arrays, schema=self.schema)

    def _write(self, table: pa.Table) -> None:
        if self.writer is None:
            self.writer = self._open(table.schema)
        if self.fmt == "parquet":
            self.writer.write_table(table, row_group_size=ROW_GROUP)
        else:
            self.writer.write_table(csv_table(table))
        self.rows += table.num_rows

    def _open(self, schema: pa.Schema):
        if self.fmt == "parquet":
            import pyarrow.parquet as pq

            codec = self.spec.compression(schema.names, self.compression)
            return pq.ParquetWriter(self.path, schema, compression=codec, **self.parquet_options())
        import pyarrow.csv as pacsv

        return pacsv.CSVWriter(self.path, csv_schema(schema))

    def close(self) -> None:
        self.flush()
        if self.writer is None:  # no rows at all: the header / an empty table still
            self._write(pa.Table.from_batches([], self.schema))
        self.writer.close()


def csv_schema(schema: pa.Schema) -> pa.Schema:
    """CSV has no categories or null type: both become strings (as the Capture export does)."""
    return pa.schema(
        [
            pa.field(f.name, pa.string())
            if pa.types.is_dictionary(f.type) or pa.types.is_null(f.type)
            else f
            for f in schema
        ]
    )


def csv_table(table: pa.Table) -> pa.Table:
    target = csv_schema(table.schema)
    cols = [
        c.cast(f.type) if c.type != f.type else c
        for c, f in zip(table.columns, target, strict=True)
    ]
    return pa.table(cols, schema=target)


class WriterThread:
    """Runs callables (chunk builders + sink writes) in order on one thread behind a bounded queue."""

    def __init__(self, depth: int = 3) -> None:
        self.queue: queue.Queue = queue.Queue(maxsize=depth)
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="table-writer", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while True:
            job = self.queue.get()
            if job is None:
                return
            if self.error is not None:
                continue  # drain: the main thread raises at its next put
            try:
                job()
            except BaseException as exc:  # noqa: BLE001 - handed to the main thread
                self.error = exc

    def put(self, job: Callable[[], None]) -> None:
        if self.error is not None:
            raise self.error
        self.queue.put(job)

    def join(self) -> None:
        """Wait for every job; raise the writer's error if one failed. Callable again
        (close, then abort on the error it raised): a second end-of-queue would wait
        forever for the finished thread to take it."""
        if self.thread.is_alive():
            self.queue.put(None)
            self.thread.join()
        if self.error is not None:
            raise self.error


def rewrite(
    sink: Sink,
    categories: dict[str, list[str]],
    order: Callable[[pa.Table], np.ndarray] | None = None,
) -> None:
    """Rewrite a finished table file: rows put in `order` (whole table in memory, rare) and/or
    dictionary columns re-coded to their final `categories` (row group by row group).
    A dataset part (`constants`) holds labels, not pandas' category codes: only its row
    order can be wrong. The `.rw` file is removed however this ends (it once outlived a
    failed rewrite)."""
    if sink.constants:
        if order is None:
            return
        categories = {}
    tmp = sink.path.with_name(sink.path.name + ".rw")
    try:
        _rewrite(sink, categories, order, tmp)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _read_back(sink: Sink, schema: pa.Schema) -> pa.Table:
    """A table file as written (`schema`: its schema; CSV read as its text columns)."""
    if sink.fmt == "parquet":
        import pyarrow.parquet as pq

        return pq.read_table(sink.path)
    import pyarrow.csv as pacsv

    return pacsv.read_csv(
        sink.path,
        convert_options=pacsv.ConvertOptions(
            column_types=csv_schema(schema),
            strings_can_be_null=True,
            quoted_strings_can_be_null=False,
        ),
    )


def _rewrite(sink: Sink, categories: dict, order, tmp: Path) -> None:
    if sink.fmt == "csv":
        if order is None:
            return  # CSV holds labels, not codes: only the row order can be wrong
        import pyarrow.csv as pacsv

        table = _read_back(sink, sink.schema)
        table = table.take(ab.numeric(np.ascontiguousarray(order(table), np.int64)))
        pacsv.write_csv(csv_table(table), tmp)
        tmp.replace(sink.path)
        return
    import pyarrow.parquet as pq

    fields = []
    for f in sink.schema:
        if f.name in categories:
            f = f.with_type(pa.dictionary(code_type(len(categories[f.name])), pa.string()))
        fields.append(f)
    schema = pa.schema(fields, metadata=sink.metadata({k: len(v) for k, v in categories.items()}))
    source = pq.ParquetFile(sink.path)
    if order is not None:
        whole = source.read()
        # the indices as an Arrow array built from the buffer: a numpy array handed to
        # take() goes through pa.array, which imports pandas (0.5-0.8 s)
        whole = whole.take(ab.numeric(np.ascontiguousarray(order(whole), np.int64)))
        parts = whole.to_batches(max_chunksize=ROW_GROUP)
    else:
        parts = (source.read_row_group(i) for i in range(source.num_row_groups))
    codec = sink.spec.compression(schema.names, sink.compression)
    with pq.ParquetWriter(tmp, schema, compression=codec, **sink.parquet_options()) as out:
        for part in parts:
            if isinstance(part, pa.RecordBatch):
                part = pa.Table.from_batches([part])
            cols = []
            for f, col in zip(schema, part.columns, strict=True):
                if f.name in categories:
                    col = _recode(col, categories[f.name], f.type)
                cols.append(col)
            out.write_table(pa.table(cols, schema=schema), row_group_size=ROW_GROUP)
    source.close()
    tmp.replace(sink.path)


def _recode(col: pa.ChunkedArray, labels: list[str], typ: pa.DataType) -> pa.ChunkedArray:
    pos = {label: i for i, label in enumerate(labels)}
    dictionary = ab.strings(labels)
    chunks = []
    for chunk in col.chunks:
        if not pa.types.is_dictionary(chunk.type):  # a null column: a table with no rows
            chunks.append(pa.nulls(len(chunk), typ))
            continue
        remap = np.array([pos[v] for v in chunk.dictionary.to_pylist()], np.int64)
        idx = ab.to_numpy(chunk.indices, fill=0).astype(np.int64)
        new = remap[idx] if remap.size else idx
        chunks.append(ab.dictionary(new, dictionary, typ.index_type))
    return pa.chunked_array(chunks, typ)
