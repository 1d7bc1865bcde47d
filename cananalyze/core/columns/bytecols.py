"""Text built column-wise: rows as NUL-padded byte matrices, joined in one pass.

Millions of lines (the `decode` text output, the SDO event messages of a polled
bus) cost a Python string operation each when formatted one by one. Built as
uint8 matrices instead, one column block per field with NUL (`PAD`) where a
row's field is shorter, the rows come out of one compaction that drops the
padding (`compact`, in C when the helper is built).
"""

from __future__ import annotations

import functools

import numpy as np

from cananalyze.runtime import speedups

PAD = 0
MAX_PARTS = 64  # column blocks the C compaction takes at once (_speedups.c)
HEX_UPPER = np.frombuffer(b"0123456789ABCDEF", np.uint8)
HEX_LOWER = np.frombuffer(b"0123456789abcdef", np.uint8)  # as bytes.hex() writes
# each byte's two hex digits as one uint16 (memory order): one gather per byte, not two
_HEX_PAIRS = np.ascontiguousarray(
    np.stack((HEX_LOWER[np.arange(256) >> 4], HEX_LOWER[np.arange(256) & 15]), axis=1)
).view(np.uint16)[:, 0]


def padded_table(texts: list[bytes]) -> np.ndarray:
    """(len(texts), longest) uint8 matrix of the texts, NUL-padded: index it by row keys.

    Filled in one masked assignment of the joined texts (row-major, as the mask is
    read), not a copy per text: tables of thousands (one per distinct EMCY code) are
    built per batch."""
    lengths = np.fromiter(map(len, texts), np.int64, len(texts))
    width = int(lengths.max()) if lengths.size else 0
    table = np.zeros((len(texts), width), np.uint8)
    table[np.arange(width)[None, :] < lengths[:, None]] = np.frombuffer(b"".join(texts), np.uint8)
    return table


def digits(values: np.ndarray, width: int) -> np.ndarray:
    """(n, width) ASCII digits of non-negative integers, zero padded.

    Unsigned, 32 bits when the values fit, and the remainder as v - 10 * (v // 10):
    numpy divides by a constant quickly but takes `%` the slow way (twice as fast).
    """
    out = np.empty((values.size, width), np.uint8)
    small = values.size == 0 or int(values.max()) < 1 << 32
    v = values.astype(np.uint32 if small else np.uint64)
    for j in range(width - 1, -1, -1):
        q = v // 10
        out[:, j] = 48 + (v - q * 10)
        v = q
    return out


def decimal(values: np.ndarray) -> np.ndarray:
    """`str(v)` of each int64 as a NUL-padded matrix (sign, then as many digits as the
    largest value has)."""
    v = np.asarray(values, np.int64)
    if v.size and 0 <= int(v.min()) and int(v.max()) < 1 << 16:
        # identifiers, lengths, node-IDs: the same matrix by one gather from a table of
        # every value's text (five passes of division and blanking were 45 ns a value)
        width = len(str(int(v.max())))
        return _small_decimals()[:, 5 - width :][v]
    neg = v < 0
    mag = v.astype(np.uint64)
    mag[neg] = np.uint64(0) - mag[neg]  # two's complement: exact for -2**63 too
    width = len(str(int(mag.max()))) if mag.size else 1
    out = np.empty((v.size, 1 + width), np.uint8)
    out[:, 1:] = digits(mag, width)
    _blank_leading(out, 1, ord("0"))
    out[:, 0] = np.where(neg, ord("-"), PAD)
    return out


@functools.cache
def _small_decimals() -> np.ndarray:
    """`decimal` of 0..65535: (65536, 6), the sign column and five digit columns."""
    table = np.empty((1 << 16, 6), np.uint8)
    table[:, 1:] = digits(np.arange(1 << 16, dtype=np.uint32), 5)
    _blank_leading(table, 1, ord("0"))
    table[:, 0] = PAD
    table.flags.writeable = False
    return table


def hex_upper(values: np.ndarray) -> np.ndarray:
    """`f"{v & 0xFFFFFFFFFFFFFFFF:X}"` of each int64 as a NUL-padded (n, 16) matrix."""
    u = np.asarray(values, np.int64).view(np.uint64)
    out = np.empty((u.size, 16), np.uint8)
    for j in range(16):
        out[:, j] = HEX_UPPER[((u >> np.uint64(60 - 4 * j)) & np.uint64(15)).astype(np.intp)]
    _blank_leading(out, 0, ord("0"))
    return out


def hex_bytes(raw: np.ndarray, length: np.ndarray) -> np.ndarray:
    """`bytes(row[:length]).hex()` of each row of a uint8 matrix, NUL-padded (n, 2 * width)."""
    n, width = raw.shape
    out = _HEX_PAIRS[raw].view(np.uint8).reshape(n, 2 * width)
    # PAD is 0: a multiply blanks the tail (a masked assignment is ~10x slower)
    out *= np.arange(2 * width)[None, :] < 2 * np.asarray(length)[:, None]
    return out


def repeat(text: bytes | str, n: int) -> np.ndarray:
    """The same text on each of n rows, as a (n, len) read-only view (no copy)."""
    raw = text.encode() if isinstance(text, str) else text
    return np.broadcast_to(np.frombuffer(raw, np.uint8), (n, len(raw)))


def left_aligned(blob: bytes, ends: np.ndarray) -> np.ndarray:
    """Compacted rows (`compact(..., with_ends=True)`) back as a matrix, each row's text
    at its start and NUL after: a column block for another compaction."""
    lengths = np.diff(ends, prepend=0)
    width = int(lengths.max()) if lengths.size else 0
    out = np.zeros((lengths.size, width), np.uint8)
    out[np.arange(width)[None, :] < lengths[:, None]] = np.frombuffer(blob, np.uint8)
    return out


def _blank_leading(m: np.ndarray, start: int, zero: int) -> None:
    """NUL for the leading `zero` digits of m[:, start:], keeping at least the last one."""
    body = m[:, start:-1]
    lead = np.logical_and.accumulate(body == zero, axis=1)
    body[lead] = PAD


def compact(parts: list[np.ndarray], n: int, with_ends: bool) -> tuple[bytes, np.ndarray | None]:
    """The rows: the matrices side by side, NUL padding left out; and, if asked, each
    row's end offset in the result."""
    compact_rows = getattr(speedups.C, "compact_rows", None)
    if compact_rows is not None and len(parts) <= MAX_PARTS:  # one pass in C, without the GIL
        # a part the same on every row (`repeat`) goes as its one row: not copied n times
        parts = [
            np.ascontiguousarray(p[:1] if n > 1 and p.strides[0] == 0 else p, np.uint8)
            for p in parts
        ]
        ends = np.empty(n, np.int64) if with_ends else None
        return compact_rows(parts, [p.shape[1] for p in parts], n, PAD, ends), ends
    if not parts:  # no columns (a batch with no rows shown): the C pass gives b"" too
        return b"", np.zeros(n, np.int64) if with_ends else None
    matrix = np.concatenate(parts, axis=1)
    keep = matrix != PAD
    return matrix[keep].tobytes(), np.cumsum(keep.sum(axis=1)) if with_ends else None


def row_bytes(blob: bytes, ends: np.ndarray) -> list[bytes]:
    """The compacted rows as bytes objects, cut at the row ends."""
    starts = [0, *ends[:-1].tolist()]
    return [blob[s:e] for s, e in zip(starts, ends.tolist(), strict=True)]


def split_rows(blob: bytes, ends: np.ndarray) -> list[str]:
    """The compacted rows as str objects (UTF-8), cut at the row ends."""
    starts = [0, *ends[:-1].tolist()]
    if blob.isascii():  # byte offsets are character offsets: slice the decoded text
        text = blob.decode("ascii")
        return [text[s:e] for s, e in zip(starts, ends.tolist(), strict=True)]
    return [blob[s:e].decode("utf-8") for s, e in zip(starts, ends.tolist(), strict=True)]


def joined_rows(parts: list[np.ndarray], n: int) -> list[str]:
    """The rows of `compact(parts)` as str objects. Rows end in a unit separator and
    the text is split there (five times faster than cutting at offsets) unless a
    row's own text holds one, which the count shows."""
    sep = np.full((n, 1), 0x1F, np.uint8)
    blob, _ = compact([*parts, sep], n, with_ends=False)
    rows = blob.decode("utf-8").split("\x1f")
    if len(rows) == n + 1:  # no row's own text holds one (no count pass, no copy)
        rows.pop()
        return rows
    blob, ends = compact(parts, n, with_ends=True)
    return split_rows(blob, ends)
