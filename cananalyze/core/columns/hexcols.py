"""Payload bytes as the buffers of an Arrow string column of lowercase hex.

The frames table has one such string per frame (tens of millions): building
the column's character and offset buffers directly avoids a Python string per
frame. The compiled helper writes them in one pass with the GIL released; the
numpy path below is the fallback and the reference.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.frames import FLAG_RTR
from cananalyze.runtime import speedups

_HEX = np.frombuffer(b"0123456789abcdef", np.uint8)


def hex_payload_buffers(
    data: np.ndarray, dlc: np.ndarray, flags: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(chars uint8, offsets int32 of n + 1) for data (n, 8): min(dlc, 8) bytes, none for RTR."""
    n = len(dlc)
    C = speedups.C
    if C is not None:
        chars = np.empty(16 * n, np.uint8)
        offsets = np.empty(n + 1, np.int32)
        used = C.hex_payload(
            np.ascontiguousarray(data, np.uint8),
            np.ascontiguousarray(dlc, np.uint8),
            np.ascontiguousarray(flags, np.uint8),
            FLAG_RTR,
            chars,
            offsets,
        )
        return chars[:used], offsets
    chars = np.empty((n, 16), np.uint8)
    chars[:, 0::2] = _HEX[data >> 4]
    chars[:, 1::2] = _HEX[data & 0x0F]
    length = np.where((flags & FLAG_RTR) != 0, 0, np.minimum(dlc, 8).astype(np.int32) * 2)
    keep = np.arange(16)[None, :] < length[:, None]
    offsets = np.zeros(n + 1, np.int32)
    np.cumsum(length, out=offsets[1:])
    return chars[keep], offsets
