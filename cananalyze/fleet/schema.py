"""The fleet dataset's schema: one fixed Arrow schema per table, whatever each log held.

A single-log export types its record tables as pandas would for that log (an SDO
column of one log is text, of another all-null; the nodes table has a column per
service seen), which is right for `load()` and wrong for a dataset: DuckDB, Spark
and `pyarrow.dataset` need every part of a table to agree. So each part is
conformed to the schema here as it is committed. The columns and their
dataset types are declared once, in `outputs/schemas` (docs/outputs.md lists them):
this module casts each part to them.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from cananalyze.outputs import schemas
from cananalyze.outputs.tables.writer import LABEL  # categories: one type for every part

# every row's lineage: which file (as given, absolute), its content, which cananalyze
LINEAGE = (("source", LABEL), ("hash", LABEL), ("version", LABEL))

# each table's columns and types, from their one declaration (outputs/schemas)
COLUMNS: dict[str, list[tuple[str, pa.DataType]]] = {
    name: table.dataset_columns() for name, table in schemas.TABLES.items()
}
TABLES = tuple(name for name, table in schemas.TABLES.items() if table.in_dataset)

# the hive partition column, typed: every reader told it is a date (pyarrow's "hive"
# partitioning reads `date=2024-03-13` as text, and DuckDB guesses text for a table whose
# only folder is `date=__HIVE_DEFAULT_PARTITION__`); Hive's partition of no value is null
PARTITION = pa.schema([pa.field("date", pa.date32())])
# the DuckDB type of each partition column (`read_parquet(..., hive_types = {...})`)
_DUCKDB_TYPES = {pa.date32(): "DATE"}


def schema(table: str) -> pa.Schema:
    """The part files' schema (the hive partition column `date` is in the path only)."""
    return pa.schema(
        [pa.field(n, t) for n, t in COLUMNS[table]] + [pa.field(n, t) for n, t in LINEAGE]
    )


def dataset_schema(table: str) -> pa.Schema:
    """A table as a reader of the dataset sees it: the part files' columns, then `date`."""
    return pa.schema([*schema(table), *PARTITION])


def partitioning():
    """The dataset's partitioning for `pyarrow.dataset` (`date` a date32)."""
    import pyarrow.dataset as pads

    return pads.partitioning(PARTITION, flavor="hive")


def duckdb_hive_types() -> str:
    """The partition columns' types as DuckDB's `hive_types` argument: `{'date': DATE}`."""
    return "{" + ", ".join(f"'{f.name}': {_DUCKDB_TYPES[f.type]}" for f in PARTITION) + "}"


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
