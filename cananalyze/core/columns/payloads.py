"""A frame batch's payloads as one Arrow column: bytes (the tables) or lowercase hex (CSV, text).

Built from buffers, never a Python object per frame: the frames table holds tens
of millions of payloads. `binary`, not `fixed_size_binary(8)`: a payload is `dlc`
bytes (none for a remote frame, up to 64 for CAN FD), and that is what a reader
wants back. As bytes the column encodes in two thirds of the time of its hex text
and is half the size (issue 23).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from cananalyze.core.columns.hexcols import hex_payload_buffers
from cananalyze.core.frames import FLAG_RTR, FrameBatch
from cananalyze.runtime import speedups

_BYTE = np.arange(8)


def payload_lengths(fb: FrameBatch) -> np.ndarray:
    """Bytes per frame: min(dlc, 8), none for a remote frame, a CAN FD payload's own length."""
    length = np.where((fb.flags & FLAG_RTR) != 0, 0, np.minimum(fb.dlc, 8)).astype(np.int32)
    for row, payload in fb.long_data.items():
        length[row] = len(payload)
    return length


def payload_bytes(fb: FrameBatch) -> pa.Array:
    """The payloads as an Arrow `binary` column; the same bytes on both paths."""
    n = len(fb)
    if speedups.C is not None and not fb.long_data:  # the classic bus: one pass in C
        return _binary(n, *_packed_c(fb))
    length = payload_lengths(fb)
    offsets = np.zeros(n + 1, np.int32)
    np.cumsum(length, out=offsets[1:])
    data = np.ascontiguousarray(fb.data, np.uint8)
    if not fb.long_data and bool((length == 8).all()):
        values = data.reshape(-1)  # the common bus: every frame 8 bytes, no copy
    else:
        short = length.copy()
        rows = np.fromiter(fb.long_data, np.int64, len(fb.long_data))
        short[rows] = 0
        mask = _BYTE[None, :] < short[:, None]
        if not rows.size:
            values = data[mask]
        else:
            values = np.empty(int(offsets[-1]), np.uint8)
            values[(offsets[:-1, None] + _BYTE[None, :])[mask]] = data[mask]
            for row, payload in fb.long_data.items():
                values[offsets[row] : offsets[row + 1]] = np.frombuffer(payload, np.uint8)
    return _binary(n, offsets, values)


def _packed_c(fb: FrameBatch) -> tuple[np.ndarray, np.ndarray]:
    """(offsets, values) of payloads of at most 8 bytes, in one pass without the GIL
    (`payload_pack`): the numpy mask and gather were 0.7 s of CPU per 10M frames."""
    n = len(fb)
    values = np.empty(8 * n, np.uint8)
    offsets = np.empty(n + 1, np.int32)
    used = speedups.C.payload_pack(
        np.ascontiguousarray(fb.data, np.uint8),
        np.ascontiguousarray(fb.dlc, np.uint8),
        np.ascontiguousarray(fb.flags, np.uint8),
        FLAG_RTR,
        values,
        offsets,
    )
    return offsets, values[:used]


def _binary(n: int, offsets: np.ndarray, values: np.ndarray) -> pa.Array:
    return pa.Array.from_buffers(
        pa.binary(), n, [None, pa.py_buffer(offsets), pa.py_buffer(values)]
    )


def payload_hex(fb: FrameBatch) -> pa.Array:
    """The payloads as an Arrow string column of lowercase hex (CSV and text are text)."""
    n = len(fb)
    chars, offsets = hex_payload_buffers(fb.data, fb.dlc, fb.flags)
    arr = pa.Array.from_buffers(pa.string(), n, [None, pa.py_buffer(offsets), pa.py_buffer(chars)])
    if fb.long_data:  # CAN FD payloads over 8 bytes: rare, patch them in
        values = arr.to_pylist()
        for row, payload in fb.long_data.items():
            values[row] = payload.hex()
        arr = pa.array(values, pa.string())
    return arr
