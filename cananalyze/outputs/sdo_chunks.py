"""The streamed SDO table's chunks as typed columns, until pandas' column types are known.

pandas types a record column over the whole column (`pandas_like.ColumnStats.decide`),
so the export spools each batch's SDO rows and converts them at the end. As Python
lists, merging, scanning, pickling and converting them was most of the export's SDO
cost. Here a chunk's column is what its values allow:

- `Numbers`: every value a float (float64) or every value an int within int64, with
  a mask of the missing ones (None, NaN);
- a large_string Arrow array: every value a str or missing;
- a list of the values, as before, when kinds mix inside the chunk (rare).

Missing values need not be told apart once the column statistics are taken: every
conversion treats None and NaN alike (but "bool", which `decide` picks only for a
column without gaps). `to_arrow` gives the same Arrow array as `pandas_like.convert`
of the values' list; whatever it cannot take directly goes through that list.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from ..sdo.fastpath import NUMBER_FIELDS, OBJECT_FIELDS, OK_CONSTANTS, RecordColumns
from . import arrow_build as ab
from . import pandas_like as pl

_EXACT = 2**53  # ints below this in magnitude print as float the way they print as int
_NONE = type(None)


@dataclass
class Numbers:
    values: np.ndarray  # float64 or int64; anything where missing
    missing: np.ndarray | None  # bool, None when no value is missing


@dataclass
class Labels:
    """A fast-path column with few distinct values (direction, constants): codes into labels."""

    codes: np.ndarray
    labels: list


Column = Numbers | pa.Array | list
Piece = np.ndarray | Labels


def _missing(v) -> bool:
    return v is None or v is pl.MISSING or (type(v) is float and math.isnan(v))


def fast_pieces(fields: RecordColumns, keep: np.ndarray | None) -> dict[str, Piece]:
    """The fast path's columns of the records at positions `keep` (None: all)."""
    a = fields.arrays
    n = len(fields) if keep is None else len(keep)

    def sel(x: np.ndarray) -> np.ndarray:
        return x if keep is None else x[keep]

    out: dict[str, Piece] = {c: sel(a[c]) for c in NUMBER_FIELDS + OBJECT_FIELDS}
    out["direction"] = Labels(sel(a["upload"]).astype(np.int8), ["download", "upload"])
    for c, v in OK_CONSTANTS.items():
        out[c] = Labels(np.zeros(n, np.int8), [v])
    return out


def _as_numbers(values: list, dtype) -> Numbers | None:
    """values (floats or ints in int64, and missing ones) as a column of dtype, else None."""
    want = float if dtype == np.float64 else int
    miss = [_missing(v) for v in values]
    if not all(m or type(v) is want for v, m in zip(values, miss, strict=True)):
        return None
    fill = math.nan if want is float else 0
    try:
        arr = np.array([fill if m else v for v, m in zip(values, miss, strict=True)], dtype)
    except OverflowError:  # an int beyond int64
        return None
    mask = np.array(miss, bool)
    return Numbers(arr, mask if mask.any() else None)


def _as_texts(values: list) -> list | None:
    """values (str and missing ones) with None for missing, else None."""
    out = [None if _missing(v) else v for v in values]
    return out if all(v is None or type(v) is str for v in out) else None


def _take(values: list, order: np.ndarray | None) -> list:
    return values if order is None else list(map(values.__getitem__, order.tolist()))


def merge(
    mine: list, fast: Piece | None, order: np.ndarray | None, stats: pl.ColumnStats
) -> Column:
    """One column of a chunk: `mine` (values read from dicts) then `fast`, taken by `order`.

    `order` (None: as they come) puts the rows in record-slot order; `stats` takes
    every value in.
    """
    stats.update(mine)
    if fast is None:
        return _classify(mine, order)
    if isinstance(fast, Labels):
        labels = fast.labels
        used = np.flatnonzero(np.bincount(fast.codes, minlength=len(labels))).tolist()
        stats.update([labels[i] for i in used], rows=len(fast.codes))
        if all(labels[i] is None for i in used):  # nothing there: mine tell the type
            return _padded(_classify(mine, None), len(fast.codes), order)
        texts = _as_texts(mine)
        if texts is None or not all(type(v) is str or v is None for v in labels):
            return _take(mine + [labels[i] for i in fast.codes.tolist()], order)
        codes = np.concatenate(
            (np.arange(len(labels), len(labels) + len(texts)), fast.codes.astype(np.int64))
        )
        codes = codes if order is None else codes[order]
        return ab.strings(labels + texts, large=True).take(ab.numeric(codes))
    if fast.dtype != object:
        stats.update_array(fast)
        got = _as_numbers(mine, fast.dtype)
        if got is None:
            return _take(mine + fast.tolist(), order)
        values = np.concatenate((got.values, fast))
        missing = None
        if got.missing is not None:
            missing = np.concatenate((got.missing, np.zeros(len(fast), bool)))
        return _numbers(values, missing, order)
    values = fast.tolist()
    stats.update(values)
    return _classify(mine + values, order)


def _classify(values: list, order: np.ndarray | None) -> Column:
    """values as Numbers or an Arrow string array when one kind (and None) holds them all."""
    types = set(map(type, values))
    real = types - {_NONE}
    given = values
    if real <= {int} or real == {float}:
        dtype = np.float64 if real == {float} else np.int64
        if _NONE in types:
            mask = np.array([v is None for v in values], bool)
            fill = math.nan if dtype == np.float64 else 0
            values = [fill if v is None else v for v in values]
        else:
            mask = None
        try:
            arr = np.array(values, dtype) if values else np.zeros(0, dtype)
        except OverflowError:  # an int beyond int64
            return _take(given, order)
        if dtype == np.float64:
            nan = np.isnan(arr)
            mask = nan if nan.any() else None
        return _numbers(arr, mask, order)
    if real == {str}:
        return ab.strings(_take(values, order), large=True)
    return _take(values, order)


def _padded(col: Column, n: int, order: np.ndarray | None) -> Column:
    """col followed by n missing values, taken by order."""
    if isinstance(col, Numbers):
        missing = np.ones(len(col.values) + n, bool)
        if col.missing is not None:
            missing[: len(col.values)] = col.missing
        elif len(col.values):
            missing[: len(col.values)] = False
        fill = np.full(n, math.nan if col.values.dtype == np.float64 else 0, col.values.dtype)
        return _numbers(np.concatenate((col.values, fill)), missing, order)
    if isinstance(col, pa.Array):
        both = pa.concat_arrays([col, pa.nulls(n, col.type)])
        return both if order is None else both.take(ab.numeric(order))
    return _take(col + [None] * n, order)


def _numbers(values: np.ndarray, missing: np.ndarray | None, order: np.ndarray | None) -> Numbers:
    if order is not None:
        values = values[order]
        missing = None if missing is None else missing[order]
    return Numbers(values, missing)


def to_arrow(col: Column, how: str) -> pa.Array:
    """`pandas_like.convert(values, how)` of the chunk column's values."""
    if isinstance(col, Numbers):
        v, miss = col.values, col.missing
        if how == "float":
            f = v.astype(np.float64)  # (a copy: the chunk is not changed)
            if miss is not None:
                f[miss] = math.nan
            return ab.numeric(f, np.isnan(f))
        if how in ("int64", "uint64") and miss is None and v.dtype == np.int64:
            return ab.numeric(v if how == "int64" else v.astype(np.uint64))
        if how == "null":
            return pa.nulls(len(v))
        if how in ("text", "textfloat") and v.dtype == np.int64 and _small(v, miss):
            return _int_texts(v, miss, how == "textfloat")
        return pl.convert(_values(col), how)
    if isinstance(col, pa.Array):
        if how in ("large", "text"):  # str(v) of a str is itself
            return col
        if how == "string":
            return col.cast(pa.string())
        return pl.convert(col.to_pylist(), how)
    return pl.convert(col, how)


def _values(col: Numbers) -> list:
    out = col.values.tolist()
    if col.missing is not None:
        for i in np.flatnonzero(col.missing).tolist():
            out[i] = None
    return out


def _small(v: np.ndarray, miss: np.ndarray | None) -> bool:
    w = v if miss is None else v[~miss]
    return not w.size or (int(w.min()) > -_EXACT and int(w.max()) < _EXACT)


def _int_texts(v: np.ndarray, miss: np.ndarray | None, as_float: bool) -> pa.Array:
    """str(v), or str(float(v)) (= str(v) + ".0" below 2**53), of each int, null where missing."""
    import pyarrow.compute as pc

    texts = pc.cast(ab.numeric(v, miss), pa.large_string())
    if not as_float:
        return texts
    zeros = ab.numeric(np.zeros(len(v), np.int64))
    suffix = ab.strings([".0"], large=True).take(zeros)
    empty = ab.strings([""], large=True).take(zeros)
    return pc.binary_join_element_wise(texts, suffix, empty)
