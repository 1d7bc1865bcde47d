"""The column types pandas would give the record tables, and pandas' Parquet metadata, without pandas.

The Capture (`load()`) builds the SDO, findings and nodes tables with
`pd.DataFrame.from_records`; Parquet needs one type per column, so a column of
mixed values is written as their text (None kept). The streaming writer must give
the Arrow types and the `pandas` schema metadata `to_parquet` would give those
tables (which makes `pd.read_parquet` restore nullable integers and the nodes
index) without importing pandas (0.5 s). `column()` repeats pandas'
inference for the value mixes records hold; tests compare it with pandas.
"""

from __future__ import annotations

import functools
import json
import math
from importlib import metadata

import numpy as np
import pyarrow as pa

from cananalyze.core.columns import arrow_build as ab


class _Missing:
    """A key the record does not have (pandas fills NaN, not None)."""


MISSING = _Missing()
_I64 = 2**63


_KIND_OF_TYPE = {type(None): "none", bool: "bool", int: "int", str: "str"}


def _kind(v) -> str:
    if v is MISSING or (isinstance(v, float) and math.isnan(v)):
        return "nan"
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, int):
        return "int"
    if isinstance(v, float):
        return "float"
    if isinstance(v, str):
        return "str"
    return "other"


def _missing(v) -> bool:
    return v is None or v is MISSING or (isinstance(v, float) and math.isnan(v))


def _text(values: list) -> pa.Array:
    # _missing inlined (a call per value was most of this); `v != v` is only NaN; a str
    # (most of a findings' measured column) is its own text, asked first
    return ab.strings(
        [
            v if type(v) is str else None if v is None or v is MISSING or v != v else str(v)
            for v in values
        ],
        large=True,
    )


class ColumnStats:
    """What pandas' inference looks at, gathered chunk by chunk (the kinds of values, int range)."""

    def __init__(self) -> None:
        self.kinds: set[str] = set()
        self.lo: int | None = None
        self.hi: int | None = None
        self.rows = 0

    def update(self, values: list | tuple, rows: int | None = None) -> set[type]:
        """Take in values (`rows`: how many rows they stand for, if not one each); their types."""
        self.rows += len(values) if rows is None else rows
        types = set(map(type, values))
        kinds = self.kinds
        for typ in types:
            kind = _KIND_OF_TYPE.get(typ)
            if kind is not None:
                kinds.add(kind)
            elif typ is float:
                floats = values if len(types) == 1 else [v for v in values if type(v) is float]
                nan = int(np.isnan(np.array(floats, np.float64)).sum())
                if nan:
                    kinds.add("nan")
                if nan < len(floats):
                    kinds.add("float")
            elif typ is _Missing:
                kinds.add("nan")
            else:
                kinds.add(_kind(values[[type(v) for v in values].index(typ)]))
        if int in types:
            ints = values if len(types) == 1 else [v for v in values if type(v) is int]
            lo, hi = min(ints), max(ints)
            self._range(lo, hi)
        return types

    def _range(self, lo: int, hi: int) -> None:
        self.lo = lo if self.lo is None else min(self.lo, lo)
        self.hi = hi if self.hi is None else max(self.hi, hi)

    def update_array(self, values: np.ndarray) -> None:
        """Take in a float64 or int64 column: as `update(values.tolist())`, without the list."""
        n = len(values)
        self.rows += n
        if not n:
            return
        if values.dtype.kind == "f":
            nan = int(np.isnan(values).sum())
            if nan:
                self.kinds.add("nan")
            if nan < n:
                self.kinds.add("float")
        elif values.dtype.kind in "iu":
            self.kinds.add("int")
            self._range(int(values.min()), int(values.max()))
        else:
            raise TypeError(f"not a numeric column: {values.dtype}")

    def decide(self, as_object: bool = False) -> tuple[str, str, str]:
        """(how to convert, pandas_type, numpy_type) for the whole column.

        as_object: the Capture casts the column to object first (the SDO `value`).
        """
        kinds = self.kinds
        real = kinds - {"nan", "none"}
        if not real:
            if "nan" in kinds and not as_object:  # NaN makes it a float column
                return "float", "float64", "float64"
            return "null", "empty", "object"
        gaps = bool(kinds & {"nan", "none"})
        if real == {"str"}:
            return ("string", "unicode", "object") if as_object else ("large", "object", "str")
        lo, hi = self.lo, self.hi
        if real == {"int"}:
            if lo < -_I64 or hi >= _I64:  # beyond int64: uint64 when it fits, else text
                if lo < 0 or hi >= 2**64 or (as_object and not gaps):
                    return "text", "object", "str"
                if not gaps:
                    return "uint64", "uint64", "uint64"
            elif not gaps:
                return ("text", "object", "str") if as_object else ("int64", "int64", "int64")
        if lo is not None and lo < 0 and hi >= _I64:  # no numeric type holds both
            return "text", "object", "str"
        if real <= {"int", "float"}:
            return ("textfloat", "object", "str") if as_object else ("float", "float64", "float64")
        if real == {"bool"} and not gaps and not as_object:
            return "bool", "bool", "bool"
        return "text", "object", "str"


_TYPES = {
    "float": pa.float64(),
    "int64": pa.int64(),
    "uint64": pa.uint64(),
    "bool": pa.bool_(),
    "string": pa.string(),
    "large": pa.large_string(),
}


def arrow_type(how: str) -> pa.DataType:
    return pa.null() if how == "null" else _TYPES.get(how, pa.large_string())


def convert(
    values: list | tuple | np.ndarray, how: str, types: set[type] | None = None
) -> pa.Array:
    """One chunk of a column as `ColumnStats.decide` said.

    values: Python values, or a float64 array (as its `tolist()`: `update_array`'s);
    types: the values' types when known (`ColumnStats.update` returns them), which
    spares a column of str its scan for the others."""
    if isinstance(values, np.ndarray):
        if how == "float" and values.dtype == np.float64:
            return ab.numeric(values, np.isnan(values))
        values = values.tolist()
    if how in ("string", "large") and types == {str}:
        return ab.strings(values, large=how == "large", nulls=False)
    if how == "null":
        return pa.nulls(len(values))
    if how == "text":
        return _text(values)
    if how == "textfloat":
        return _text([None if _missing(v) else float(v) for v in values])
    if how == "float":  # ints, floats, None and NaN only: numpy reads None as NaN
        if _Missing in set(map(type, values)):
            values = [None if v is MISSING else v for v in values]
        floats = np.array(values, np.float64)
        return ab.numeric(floats, np.isnan(floats))
    if how in ("string", "large"):
        return ab.strings([v if type(v) is str else None for v in values], large=how == "large")
    if how == "bool":
        return ab.numeric(np.array(values, bool))
    if how == "int64" and int in set(map(type, values)) and len(set(map(type, values))) == 1:
        return ab.numeric(np.array(values, np.int64))
    return ab.optional_ints([None if _missing(v) else v for v in values], _TYPES[how])


def column(values: list, as_object: bool = False) -> tuple[pa.Array, str, str]:
    """(Arrow array, pandas_type, numpy_type) of one from_records column, mixed values as text."""
    stats = ColumnStats()
    stats.update(values)
    how, pandas_type, numpy_type = stats.decide(as_object)
    return convert(values, how), pandas_type, numpy_type


def field_meta(name: str, pandas_type: str, numpy_type: str, meta: dict | None = None) -> dict:
    return {
        "name": name,
        "field_name": name,
        "pandas_type": pandas_type,
        "numpy_type": numpy_type,
        "metadata": meta,
    }


def categorical_meta(name: str, n: int) -> dict:
    code = "int8" if n < 128 else "int16" if n < 32768 else "int32"
    return field_meta(name, "categorical", code, {"num_categories": n, "ordered": False})


def code_type(n: int) -> pa.DataType:
    """Index type pandas gives a categorical of n categories."""
    return pa.int8() if n < 128 else pa.int16() if n < 32768 else pa.int32()


def schema_metadata(columns: list[dict], index: str | None = None) -> dict[bytes, bytes]:
    """The `pandas` key pyarrow writes for a DataFrame (`to_parquet`), so read-back matches."""
    meta = {
        "index_columns": [index] if index else [],
        "column_indexes": (
            [
                {
                    "name": None,
                    "field_name": None,
                    "pandas_type": "unicode",
                    "numpy_type": "str",
                    "metadata": {"encoding": "UTF-8"},
                }
            ]
            if index
            else []
        ),
        "columns": columns,
        "attributes": {},
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": _pandas_version(),
    }
    return {b"pandas": json.dumps(meta).encode()}


@functools.cache
def _pandas_version() -> str:
    """Asked once a process: the metadata lookup parses pandas' METADATA (4 ms each time,
    three times per export; a fleet worker exports thousands of logs)."""
    try:
        return metadata.version("pandas")
    except metadata.PackageNotFoundError:
        return "0"
