"""JSON text for whole columns at once: one byte buffer plus offsets, no str per row.

Exporters that write a JSON document per frame (MCAP topics) build them column-wise:
numbers are formatted by pyarrow's C++ casts (shortest round-trip text for floats,
like `repr`), fixed text comes from a template, and `join` glues the pieces row by
row. A million frame documents take well under a second this way; one f-string or
`json.dumps` per frame took seconds.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from cananalyze.core.columns import arrow_build as ab

if TYPE_CHECKING:
    import pyarrow as pa


@dataclass
class Texts:
    """n byte strings stored end to end: row i is data[offsets[i]:offsets[i + 1]]."""

    data: np.ndarray  # uint8
    offsets: np.ndarray  # int64, n + 1 entries, offsets[0] == 0

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def __getitem__(self, i: int) -> bytes:
        return self.data[self.offsets[i] : self.offsets[i + 1]].tobytes()

    @property
    def lengths(self) -> np.ndarray:
        return np.diff(self.offsets)

    @classmethod
    def from_list(cls, items: list[bytes]) -> Texts:
        """For the rare streams (events, states) that are built one dict at a time."""
        lengths = np.fromiter((len(b) for b in items), np.int64, len(items))
        offsets = np.zeros(len(items) + 1, np.int64)
        np.cumsum(lengths, out=offsets[1:])
        return cls(np.frombuffer(b"".join(items), np.uint8), offsets)

    @classmethod
    def from_arrow(cls, arr: pa.Array) -> Texts:
        import pyarrow as pa

        if isinstance(arr, pa.ChunkedArray):
            arr = arr.combine_chunks()
        _, off_buf, data_buf = arr.buffers()
        wide = pa.types.is_large_string(arr.type) or pa.types.is_large_binary(arr.type)
        offsets = np.frombuffer(off_buf, np.int64 if wide else np.int32)
        offsets = offsets[arr.offset : arr.offset + len(arr) + 1].astype(np.int64)
        data = np.frombuffer(data_buf, np.uint8) if data_buf is not None else np.zeros(0, np.uint8)
        return cls(data[offsets[0] : offsets[-1]], offsets - offsets[0])

    @classmethod
    def concat(cls, parts: list[Texts]) -> Texts:
        if not parts:
            return cls(np.zeros(0, np.uint8), np.zeros(1, np.int64))
        if len(parts) == 1:
            return parts[0]
        bases = np.cumsum([0] + [len(p.data) for p in parts[:-1]])
        offsets = np.concatenate(
            [parts[0].offsets[:1]] + [p.offsets[1:] + b for p, b in zip(parts, bases, strict=True)]
        )
        return cls(np.concatenate([p.data for p in parts]), offsets)


def number_text(values: np.ndarray) -> pa.Array:
    """JSON numbers (or true/false) as a string array; NaN and inf become null.

    Floats go through float64 first so the text is the value the other outputs
    (Parquet, rerun) hold; integers keep their full 64-bit precision. Arrays made from
    buffers and kernels called by name (`arrow_build`): pa.array and pa.scalar import
    pandas (~150 ms CPU) in pyarrow 26, pyarrow.compute its wrappers (~60 ms).
    """
    import pyarrow as pa

    values = np.asarray(values)
    if values.dtype == bool or np.issubdtype(values.dtype, np.integer):
        return ab.cast(ab.numeric(values), pa.string())
    v = values.astype(np.float64, copy=False)
    text = ab.cast(ab.numeric(v), pa.string())
    finite = np.isfinite(v)
    if not finite.all():
        text = ab.kernel("if_else", [ab.numeric(finite), text, _scalar("null")])
    return text


def join(parts: list) -> Texts:
    """Concatenate row by row; parts are str (same in every row) or string arrays."""
    args = [_scalar(p) if isinstance(p, str) else p for p in parts]
    return Texts.from_arrow(ab.kernel("binary_join_element_wise", [*args, _scalar("")]))


def _scalar(text: str):
    """A string scalar (a one-row array's first value: no pandas check)."""
    return ab.strings([text], nulls=False)[0]


def object_template(names: list[str], columns: list[pa.Array]) -> list:
    """The parts of `{"name": value, ...}` for `join`, value texts already JSON."""
    parts: list = []
    for k, (name, col) in enumerate(zip(names, columns, strict=True)):
        parts.append(("{" if k == 0 else ",") + json.dumps(name) + ":")
        parts.append(col)
    parts.append("}" if names else "{}")
    return parts
