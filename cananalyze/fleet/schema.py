"""The fleet dataset's schema: one fixed Arrow schema per table, whatever each log held.

A single-log export types its record tables as pandas would for that log (an SDO
column of one log is text, of another all-null; the nodes table has a column per
service seen), which is right for `load()` and wrong for a dataset: DuckDB, Spark
and `pyarrow.dataset` need every part of a table to agree. So each part is
conformed to the schema here as it is committed. The column names come from the
export's own tables (`outputs/tables/stream`: frames, signals, events; the SDO,
findings and node columns): this module only fixes their types. docs/fleet.md
lists them.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from cananalyze.decode.node_tally import IDENTITY_KEYS
from cananalyze.outputs.tables.stream import (
    EVENTS_BUS,
    FINDING_COLUMNS,
    FRAMES,
    SDO_COLUMNS,
    SIGNALS_BUS,
)
from cananalyze.outputs.tables.writer import LABEL  # categories: one type for every part
from cananalyze.protocol.services import SERVICE_NAMES

# every row's lineage: which file (as given, absolute), its content, which cananalyze
LINEAGE = (("source", LABEL), ("hash", LABEL), ("version", LABEL))


def _from_spec(spec) -> list[tuple[str, pa.DataType]]:
    """The columns the export's writer gives a dataset part (`writer.Sink` with constants)."""
    return [(name, LABEL if typ is None else typ) for name, typ in spec.fields]


_SDO_TYPES = {
    "t_start": pa.float64(),
    "t": pa.float64(),
    "latency_ms": pa.float64(),
    "node": pa.int16(),
    "index": pa.int32(),
    "subindex": pa.int16(),
    "size": pa.int64(),
    "abort_code": pa.int64(),
}
_FINDING_TYPES = {"t": pa.float64(), "t_rel": pa.float64(), "node": pa.int16()}
_FINDING_TYPES["cob_id"] = _FINDING_TYPES["line"] = pa.int64()
_NODE_NUMBERS = ("device_type", "vendor_id", "product_code", "revision", "serial")

COLUMNS: dict[str, list[tuple[str, pa.DataType]]] = {
    "frames": _from_spec(FRAMES),
    "signals": _from_spec(SIGNALS_BUS),  # `bus`: a log of several buses (else null)
    "events": _from_spec(EVENTS_BUS),  # `bus`: a log of several buses (else null)
    # SDO values are text: one log decodes a REAL32, another a VISIBLE_STRING
    "sdo": [(c, _SDO_TYPES.get(c, pa.string())) for c in SDO_COLUMNS]
    + [("bus", pa.string())],  # a log of several buses: which one (else null)
    # measured/expected: a number for one rule, a state name for another
    "findings": [(c, _FINDING_TYPES.get(c, pa.string())) for c in FINDING_COLUMNS]
    + [("bus", pa.string())],  # a log of several buses: which one (else null)
    "nodes": [("node", pa.int16()), ("frames", pa.int64())]
    + [(f"frames_{s}", pa.int64()) for s in SERVICE_NAMES]
    + [("last_state", pa.string()), ("last_state_t", pa.float64())]
    + [(k, pa.int64() if k in _NODE_NUMBERS else pa.string()) for k in IDENTITY_KEYS]
    + [("profile", pa.string()), ("identified_by", pa.string())]
    + [("bus", pa.string())],  # a log of several buses: one row per bus and node
    "logs": [
        ("format", pa.string()),
        ("size", pa.int64()),
        ("frames", pa.int64()),
        ("t_first", pa.float64()),
        ("t_last", pa.float64()),
        ("date_from", pa.string()),  # "log": the log's own times; "mtime": the file's
        ("status", pa.string()),  # ok | failed
        ("error", pa.string()),
        ("seconds", pa.float64()),
        ("cpu_seconds", pa.float64()),  # the worker process's, threads included
        ("peak_rss_mb", pa.float64()),  # the worker's peak resident memory so far
        ("skipped_lines", pa.int64()),
        ("findings", pa.int64()),
        ("violations", pa.int64()),
        ("config", pa.string()),  # sha256 of the options and the files they name
    ],
}
TABLES = ("frames", "signals", "sdo", "events", "findings", "nodes", "logs")


def schema(table: str) -> pa.Schema:
    """The part files' schema (the hive partition column `date` is in the path only)."""
    return pa.schema(
        [pa.field(n, t) for n, t in COLUMNS[table]] + [pa.field(n, t) for n, t in LINEAGE]
    )


def _cast(col: pa.ChunkedArray | pa.Array, typ: pa.DataType, n: int) -> pa.Array:
    """One column to its fleet type: null-typed (no values in this log) to typed nulls,
    NaN (pandas' missing number) to null before an integer cast, numbers to text."""
    if col.type == typ:
        return col
    if pa.types.is_null(col.type):
        return pa.nulls(n, typ)
    if pa.types.is_dictionary(col.type) and typ != LABEL:
        col = col.cast(col.type.value_type)
    if pa.types.is_floating(col.type) and pa.types.is_integer(typ):
        col = pc.if_else(pc.is_nan(col), pa.scalar(None, col.type), col)
    if typ == LABEL and not pa.types.is_dictionary(col.type):
        return pc.dictionary_encode(col.cast(pa.string())).cast(LABEL)
    return col.cast(typ)


def constant(value: str, n: int) -> pa.DictionaryArray:
    """A column of one repeated label: one dictionary entry and n zero codes."""
    return pa.DictionaryArray.from_arrays(pa.array(np.zeros(n, np.int32)), pa.array([value]))


def conform(table: pa.Table, name: str, lineage: dict[str, str]) -> pa.Table:
    """`table` (one row group of a log's export) in the fleet schema, lineage appended.

    Columns the log lacks are null (node counts of a service never seen: 0); a column
    the schema does not know is an error here, not a silently dropped value.
    """
    n = table.num_rows
    known = {c for c, _ in COLUMNS[name]}
    extra = [c for c in table.column_names if c not in known and not c.startswith("__")]
    if extra:
        raise ValueError(f"{name} table: columns {extra} are not in the fleet schema")
    arrays = []
    for col, typ in COLUMNS[name]:
        if col in table.column_names:
            arrays.append(_cast(table.column(col), typ, n))
        elif name == "nodes" and col.startswith("frames_"):
            arrays.append(pa.array(np.zeros(n, np.int64)))
        else:
            arrays.append(pa.nulls(n, typ))
    arrays += [constant(lineage[c], n) for c, _ in LINEAGE]
    return pa.Table.from_arrays(arrays, schema=schema(name))


class Conform:
    """What TableSink asks of a record table written as a dataset part (its `conform`)."""

    def __init__(self, lineage: dict[str, str]) -> None:
        self.lineage = lineage

    def schema(self, name: str) -> pa.Schema:
        return schema(name)

    def table(self, name: str, table: pa.Table) -> pa.Table:
        return conform(table, name, self.lineage)
