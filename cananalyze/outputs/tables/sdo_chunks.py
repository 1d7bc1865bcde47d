"""The streamed SDO table's chunks as typed columns, without a Python list per column.

pandas types a record column over the whole column (`pandas_like.ColumnStats.decide`),
so the export takes each batch's statistics in (`take_in`), spools the batch's pieces
(the tracker's values as lists, the fast path's as numpy `fast_pieces`) and converts
them once the types are known (or as they come while the types so far hold). As
Python lists, merging, scanning, pickling and converting them was most of the
export's SDO cost. `merge` makes a chunk's column what its values allow:

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

from cananalyze.core.columns import arrow_build as ab
from cananalyze.core.columns.hexcols import hex_payload_buffers
from cananalyze.core.sdo_records import NUMBER_FIELDS, OK_CONSTANTS, RecordColumns
from cananalyze.outputs.tables import pandas_like as pl

_EXACT = 2**53  # ints below this in magnitude print as float the way they print as int
_NONE = type(None)


@dataclass
class Numbers:
    values: np.ndarray  # float64 or int64; anything where missing
    missing: np.ndarray | None  # bool, None when no value is missing


@dataclass
class Hex:
    """The fast path's data column: hex text of each row's first `length` bytes of `raw`."""

    raw: np.ndarray  # (n, 4) uint8
    length: np.ndarray  # bytes used (0 for none: "")


@dataclass
class Labels:
    """A fast-path column with few distinct values (direction, constants): codes into labels."""

    codes: np.ndarray
    labels: list


Column = Numbers | pa.Array | list
Piece = np.ndarray | Numbers | Labels | Hex | pa.Array


def _missing(v) -> bool:
    return v is None or v is pl.MISSING or (type(v) is float and math.isnan(v))


def fast_pieces(fields: RecordColumns, keep: np.ndarray | None) -> dict[str, Piece]:
    """The fast path's columns of the records at positions `keep` (None: all)."""
    a = fields.arrays
    n = len(fields) if keep is None else len(keep)

    def sel(x: np.ndarray) -> np.ndarray:
        return x if keep is None else x[keep]

    out: dict[str, Piece] = {c: sel(a[c]) for c in NUMBER_FIELDS}
    if "value_int" in a:
        none = sel(a["value_none"])
        out["value"] = Numbers(sel(a["value_int"]), none if none.any() else None)
    else:
        out["value"] = sel(a["value"])
    out["data"] = Hex(sel(a["raw"]), sel(a["data_len"]))
    out["name"] = Labels(sel(a["name_code"]), fields.name_labels)
    words = sel(a["words"])  # mostly None: then one label, as a constant column is written
    none = not (words != None).any()  # noqa: E711 (elementwise)
    out["words"] = Labels(np.zeros(n, np.int8), [None]) if none else words
    out["direction"] = Labels(sel(a["upload"]).astype(np.int8), ["download", "upload"])
    for c, v in OK_CONSTANTS.items():
        out[c] = Labels(np.zeros(n, np.int8), [v])
    return out


def hex_strings(raw: np.ndarray, length: np.ndarray) -> pa.Array:
    """large_string column of the hex text of each row's first `length` bytes.

    The frames table's payload column builder (`hexcols`, compiled when built)
    does the work; the SDO table's pandas-like type is large_string.
    """
    m = len(raw)
    padded = np.zeros((m, 8), np.uint8)
    padded[:, : raw.shape[1]] = raw
    chars, offsets = hex_payload_buffers(
        padded, np.asarray(length, np.uint8), np.zeros(m, np.uint8)
    )
    return pa.Array.from_buffers(
        pa.large_string(),
        m,
        [None, pa.py_buffer(offsets.astype(np.int64)), pa.py_buffer(chars)],
    )


def _from_buffers(lengths: np.ndarray, data: np.ndarray, missing: np.ndarray | None) -> pa.Array:
    n = len(lengths)
    offsets = np.zeros(n + 1, np.int64)
    np.cumsum(lengths, out=offsets[1:])
    return pa.Array.from_buffers(
        pa.large_string(),
        n,
        [ab._validity(missing), pa.py_buffer(offsets), pa.py_buffer(np.ascontiguousarray(data))],
    )


def _parts(arr: pa.Array) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(offsets, data bytes, missing mask or None) of a large_string array."""
    n = len(arr)
    validity, offsets, data = arr.buffers()
    off = np.frombuffer(offsets, np.int64, n + 1, arr.offset * 8)
    raw = np.frombuffer(data, np.uint8) if data is not None else np.zeros(0, np.uint8)
    missing = None
    if arr.null_count:
        bits = np.unpackbits(np.frombuffer(validity, np.uint8), bitorder="little")
        missing = ~bits[arr.offset : arr.offset + n].astype(bool)
    return off, raw, missing


def take_strings(arr: pa.Array, order: np.ndarray) -> pa.Array:
    """arr[order] of a string array (pyarrow's take: ~10x a numpy gather of the bytes).

    The kernel by name, as pc.take calls it: importing pyarrow.compute builds a Python
    wrapper per kernel (~60 ms of CPU), which an export needs nowhere else."""
    return ab.kernel("take", [arr, ab.numeric(np.asarray(order, np.int64))])


def _concat(parts: list[pa.Array]) -> pa.Array:
    parts = [p for p in parts if len(p)]
    if len(parts) == 1:
        return parts[0]
    return pa.concat_arrays(parts) if parts else ab.strings([], large=True)


def _as_numbers(values: list, dtype) -> Numbers | None:
    """values (floats or ints in int64, and missing ones) as a column of dtype, else None."""
    want = float if dtype == np.float64 else int
    types = set(map(type, values))
    if types <= {want}:  # the common case: no gaps
        miss = None
    else:
        miss = [_missing(v) for v in values]
        if not all(m or type(v) is want for v, m in zip(values, miss, strict=True)):
            return None
        fill = math.nan if want is float else 0
        values = [fill if m else v for v, m in zip(values, miss, strict=True)]
    try:
        arr = np.array(values, dtype) if values else np.zeros(0, dtype)
    except OverflowError:  # an int beyond int64
        return None
    mask = None if miss is None else np.array(miss, bool)
    return Numbers(arr, mask if mask is not None and mask.any() else None)


def _as_texts(values: list) -> list | None:
    """values (str and missing ones) with None for missing, else None."""
    out = [None if _missing(v) else v for v in values]
    return out if all(v is None or type(v) is str for v in out) else None


def _take(values: list, order: np.ndarray | None) -> list:
    return values if order is None else list(map(values.__getitem__, order.tolist()))


def take_in(stats: pl.ColumnStats, mine: list, fast: Piece | None) -> None:
    """What `stats.update(mine + values of fast)` takes in, without the values' list."""
    stats.update(mine)
    if fast is None:
        return
    if isinstance(fast, Labels):
        if len(fast.labels) == 1:  # a constant column: code 0 on every row
            used = [0] if len(fast.codes) else []
        else:
            used = np.flatnonzero(np.bincount(fast.codes, minlength=len(fast.labels))).tolist()
        stats.update([fast.labels[i] for i in used], rows=len(fast.codes))
    elif isinstance(fast, Hex):
        stats.update(["x"] if len(fast.length) else [], rows=len(fast.length))
    elif isinstance(fast, pa.Array):
        n = len(fast)
        stats.update((["x"] if fast.null_count < n else []) + [None] * (fast.null_count > 0), n)
    elif isinstance(fast, Numbers) or fast.dtype != object:
        if not isinstance(fast, Numbers):
            fast = Numbers(fast, None)
        gaps = 0 if fast.missing is None else int(fast.missing.sum())
        stats.update_array(fast.values if not gaps else fast.values[~fast.missing])
        stats.update([None] if gaps else [], rows=gaps)
    else:
        stats.update(fast.tolist())


def merge(mine: list, fast: Piece | None, order: np.ndarray | None) -> Column:
    """One column of a chunk: `mine` (values read from dicts) then `fast`, taken by `order`.

    `order` (None: as they come) puts the rows in record-slot order. Numpy and
    Arrow work only (but for mixes of kinds): the export runs it on the writer thread.
    """
    if fast is None:
        return _classify(mine, order)
    if isinstance(fast, Hex):
        fast = hex_strings(fast.raw, fast.length)
    if isinstance(fast, Labels):
        labels = fast.labels
        used = np.flatnonzero(np.bincount(fast.codes, minlength=len(labels))).tolist()
        if all(labels[i] is None for i in used):  # nothing there: mine tell the type
            return _padded(_classify(mine, None), len(fast.codes), order)
        texts = _as_texts(mine)
        if texts is None or not all(type(v) is str or v is None for v in labels):
            return _take(mine + [labels[i] for i in fast.codes.tolist()], order)
        codes = np.concatenate(
            (np.arange(len(labels), len(labels) + len(texts)), fast.codes.astype(np.int64))
        )
        return take_strings(ab.strings(labels + texts, large=True), _ordered(codes, order))
    if isinstance(fast, pa.Array):
        texts = _as_texts(mine)
        if texts is None:
            return _take(mine + fast.to_pylist(), order)
        both = _concat([ab.strings(texts, large=True), fast])
        return both if order is None else take_strings(both, order)
    if isinstance(fast, Numbers) or fast.dtype != object:
        if not isinstance(fast, Numbers):
            fast = Numbers(fast, None)
        got = _as_numbers(mine, fast.values.dtype)
        if got is None:
            return _take(mine + _values(fast), order)
        values = np.concatenate((got.values, fast.values))
        missing = None
        if got.missing is not None or fast.missing is not None:
            missing = np.concatenate(
                [
                    np.zeros(len(x.values), bool) if x.missing is None else x.missing
                    for x in (got, fast)
                ]
            )
        return _numbers(values, missing, order)
    return _classify(mine + fast.tolist(), order)


def _ordered(x: np.ndarray, order: np.ndarray | None) -> np.ndarray:
    return x if order is None else x[order]


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
        texts = ab.strings(values, large=True)
        return texts if order is None else take_strings(texts, order)
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
        both = _concat([col, pa.nulls(n, col.type)])
        return both if order is None else take_strings(both, order)
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
            return _small_strings(col)
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


def _small_strings(col: pa.Array) -> pa.Array:
    """The large_string column as string (32-bit offsets)."""
    off, raw, missing = _parts(col)
    data = raw[int(off[0]) :]
    off = off - off[0]
    if off[-1] >= 2**31:
        return pl.convert(col.to_pylist(), "string")
    return pa.Array.from_buffers(
        pa.string(),
        len(col),
        [ab._validity(missing), pa.py_buffer(off.astype(np.int32)), pa.py_buffer(data)],
    )


_POW10 = 10 ** np.arange(19, dtype=np.int64)


def _int_texts(v: np.ndarray, miss: np.ndarray | None, as_float: bool) -> pa.Array:
    """str(v), or str(float(v)) (= str(v) + ".0" below 2**53), of each int, null where missing.

    Digits by a division per decimal place into a right-aligned byte matrix (a
    third of numpy's int-to-bytes cast); |v| < 2**53 here.
    """
    n = len(v)
    neg = v < 0
    a = np.abs(v)
    digits = np.maximum(np.searchsorted(_POW10, a, side="right"), 1)
    length = digits + neg
    width = int(length.max()) if n else 1
    tail = 2 if as_float else 0
    text = np.empty((n, width + tail), np.uint8)
    for k in range(int(digits.max()) if n else 0):
        a, d = np.divmod(a, 10)
        text[:, width - 1 - k] = d + 48
    rows = np.flatnonzero(neg)
    text[rows, width - length[rows]] = ord("-")
    if as_float:
        text[:, width] = ord(".")
        text[:, width + 1] = ord("0")
    length += tail
    if miss is not None:
        length[miss] = 0
    used = np.arange(width + tail) >= (width + tail - length)[:, None]
    return _from_buffers(length, text[used], miss)
