"""Arrow arrays from numpy buffers and plain lists, without `pa.array`.

`pa.array` asks pyarrow's pandas shim whether its argument is a pandas object,
which imports pandas (0.5 s, 60 MB) the first time; the streaming table writer
never needs pandas, so it builds arrays from buffers (zero-copy for numpy
columns) through these helpers.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa


def kernel(name: str, args: list, options=None) -> pa.Array:
    """Arrow's compute function `name`, called by its registry name as `pc.<name>` calls
    it: importing pyarrow.compute builds a Python wrapper per kernel (~60 ms of CPU) that
    nothing here needs."""
    try:
        from pyarrow._compute import call_function
    except ImportError:  # pragma: no cover - private module gone: the public one
        from pyarrow.compute import call_function
    return call_function(name, args, options)


def cast(arr: pa.Array, typ: pa.DataType) -> pa.Array:
    """`pc.cast(arr, typ)` (safe) through `kernel`."""
    try:
        from pyarrow._compute import CastOptions
    except ImportError:  # pragma: no cover - private module gone: the public one
        from pyarrow.compute import CastOptions
    return kernel("cast", [arr], CastOptions.safe(typ))


def _validity(mask: np.ndarray | None) -> pa.Buffer | None:
    """Arrow validity bitmap (1 = valid) from a numpy mask of missing values."""
    if mask is None or not mask.any():
        return None
    return pa.py_buffer(np.packbits(~mask, bitorder="little"))


def numeric(values: np.ndarray, mask: np.ndarray | None = None, typ=None) -> pa.Array:
    """A numeric column over the numpy buffer (copied only when not contiguous)."""
    values = np.ascontiguousarray(values)
    if values.dtype == bool:  # Arrow booleans are bits
        bits = pa.py_buffer(np.packbits(values, bitorder="little"))
        return pa.Array.from_buffers(pa.bool_(), len(values), [_validity(mask), bits])
    typ = typ or pa.from_numpy_dtype(values.dtype)
    return pa.Array.from_buffers(typ, len(values), [_validity(mask), pa.py_buffer(values)])


def strings(values: list, large: bool = False, nulls: bool = True) -> pa.Array:
    """A (large_)string column from str/None values (`nulls=False`: str only, not
    looked at for None).

    Mostly ASCII (event messages, SDO text): then one join and one encode for the
    column, lengths from `len`, instead of an encode per value (half the time).
    """
    n = len(values)
    mask = np.array([v is None for v in values], bool) if nulls else None
    texts = ["" if v is None else v for v in values] if nulls and mask.any() else values
    joined = "".join(texts)
    if joined.isascii():
        data = joined.encode("ascii")
        lengths = np.fromiter(map(len, texts), np.int64, n)
    else:
        encoded = [t.encode() for t in texts]
        data = b"".join(encoded)
        lengths = np.fromiter(map(len, encoded), np.int64, n)
    offsets = np.zeros(n + 1, np.int64 if large else np.int32)
    np.cumsum(lengths, out=offsets[1:])
    typ = pa.large_string() if large else pa.string()
    return pa.Array.from_buffers(
        typ, n, [_validity(mask), pa.py_buffer(offsets), pa.py_buffer(data)]
    )


def optional_ints(values: list, typ: pa.DataType) -> pa.Array:
    """An integer column from int/None values."""
    mask = np.fromiter((v is None for v in values), bool, len(values))
    dense = np.fromiter((0 if v is None else v for v in values), typ.to_pandas_dtype(), len(values))
    return numeric(dense, mask, typ)


def dictionary(codes: np.ndarray, labels: pa.Array, index_type: pa.DataType) -> pa.Array:
    """Dictionary column: codes (any int dtype) into labels."""
    idx = numeric(codes.astype(index_type.to_pandas_dtype(), copy=False), typ=index_type)
    return pa.DictionaryArray.from_arrays(idx, labels)


def to_numpy(column: pa.Array | pa.ChunkedArray, fill=None) -> np.ndarray:
    """A fixed-width column's values as numpy, nulls set to `fill`, read from the buffers.

    pyarrow's own `to_numpy` imports pandas (pyarrow 26, zero-copy included).
    """
    chunks = column.chunks if isinstance(column, pa.ChunkedArray) else [column]
    dtype = np.dtype(column.type.to_pandas_dtype())
    parts = []
    for c in chunks:
        validity, data = c.buffers()[:2]
        values = np.frombuffer(data, dtype, len(c), c.offset * dtype.itemsize).copy()
        if c.null_count and validity is not None:
            bits = np.unpackbits(np.frombuffer(validity, np.uint8), bitorder="little")
            values[~bits[c.offset : c.offset + len(c)].astype(bool)] = fill
        parts.append(values)
    return np.concatenate(parts) if parts else np.zeros(0, dtype)
