"""The page's compact encodings: bytes as 7-bit text, plotted arrays as rounded integers.

An hour-long log's page is mostly plotly.js and the plots' points, neither of which is
read as text. Both travel gzip-compressed in `<script type="text/plain">` elements as
7 bits per character (`text7`): script text keeps every character but NUL, CR and `<`
(which could close the element), so those three values are written as U+0100 + value
(two bytes in UTF-8) and the rest as themselves. That is 1.17 bytes per byte where
base64 takes 1.33: 0.25 MB less plotly.js. The page's loader undoes it (`page.LOADER`).

A plotted array (`Packed`) is rounded to a power of ten the eye cannot tell from the
value (a few ten-thousandths of its range, never finer than the caller's resolution:
a microsecond of a period in ms), and sent as 16- or 32-bit integers, offsets from the
smallest or differences from the previous (whichever gzip takes smaller: a steady time
axis costs nothing). Plotted values only: the statistics in the page's text are exact.
"""

from __future__ import annotations

import gzip
import json
import math
import struct
import zlib

import numpy as np

ESCAPED = (0, 13, 60)  # NUL (read as U+FFFD), CR (read as LF), '<' (could close the script)
# an array's range in at most this many steps: offsets fit int16, a step is a tenth of a pixel
LEVELS = 30_000


def text7(raw: bytes) -> str:
    """`raw` as 7 bits per character, most significant first, the last padded with zero
    bits (the loader's `unpack7` reads it back). Seven bytes make eight characters: one
    56-bit integer per seven bytes, not a byte per bit."""
    n = len(raw)
    groups = np.frombuffer(raw + b"\0" * (-n % 7), np.uint8).reshape(-1, 7)
    word = np.zeros(groups.shape[0], np.uint64)
    for i in range(7):
        word |= groups[:, i].astype(np.uint64) << np.uint64(48 - 8 * i)
    codes = np.empty((groups.shape[0], 8), np.uint16)
    for j in range(8):
        codes[:, j] = (word >> np.uint64(49 - 7 * j)) & np.uint64(0x7F)
    codes = codes.ravel()[: -(-8 * n // 7)]
    for v in ESCAPED:
        codes[codes == v] = 0x100 + v
    return codes.astype("<u2").tobytes().decode("utf-16-le")


def gzip7(raw: bytes) -> str:
    """gzip, then `text7`: what the loader's `inflate` reads."""
    return text7(gzip.compress(raw, compresslevel=9, mtime=0))


class Packed:
    """A plotted array, rounded (see the module's docstring); `resolution`: the finest
    step worth sending (a power of ten), e.g. 1e-3 for milliseconds measured in µs;
    `exact`: that step whatever the range (values read in a hover, as the NMT lanes')."""

    def __init__(self, values, resolution: float | None = None, exact: bool = False) -> None:
        self.values = np.asarray(values, np.float64)
        self.resolution = resolution
        self.exact = exact and resolution is not None

    def exponent(self) -> int:
        v = self.values
        if self.exact:
            return round(math.log10(self.resolution))
        v = v[np.isfinite(v)]
        if v.size == 0:
            return 0
        lo, hi = float(v.min()), float(v.max())
        if hi > lo:
            e = math.ceil(math.log10((hi - lo) / LEVELS))
        else:
            e = math.floor(math.log10(abs(lo))) - 6 if lo else 0
        if self.resolution is not None:
            e = max(e, round(math.log10(self.resolution)))
        if e != 0 and np.array_equal(v, np.rint(v)) and self.resolution is None:
            e = 0  # integers (a counter, a raw value) stay exact
        return e

    def encode(self) -> tuple[int, int, int, int, bytes]:
        """(exponent, first integer, form, bytes per value, the values' bytes), as `Blob`
        documents them."""
        e = self.exponent()
        v = self.values
        if v.size == 0:
            return e, 0, 0, 2, b""
        scaled = v * 10.0**-e if e < 0 else v / 10.0**e
        if not np.isfinite(scaled).all() or np.abs(scaled).max() >= 2**53:
            return e, 0, 2, 8, v.astype("<f8").tobytes()  # as they are (NaN: a gap)
        k = np.rint(scaled).astype(np.int64)
        best = None
        for delta in (0, 1):
            k0 = int(k[0]) if delta else int(k.min())
            d = np.diff(k, prepend=k[0]) if delta else k - k0
            size = 2 if -32768 <= d.min() and d.max() <= 32767 else 4
            if size == 4 and (d.min() < -(2**31) or d.max() >= 2**31):
                continue  # a span beyond int32 (no plot needs it): the other form
            data = d.astype(f"<i{size}").tobytes()
            cost = len(zlib.compress(data, 1))
            if best is None or cost < best[0]:
                best = (cost, (e, k0, delta, size, data))
        if best is None:  # both beyond int32: the float64 values themselves, rounded
            return e, 0, 2, 8, np.round(v, -e).astype("<f8").tobytes()
        return best[1]


class Blob:
    """The plots' figures as one gzip stream: JSON, then the arrays' bytes.

    Layout: uint32 (little-endian) length of the JSON text, the JSON (UTF-8), zero bytes
    to a multiple of 8, then each array's bytes at its offset (a multiple of 8) from
    there. In the JSON an array is {"q": [offset, count, bytes per value, form,
    first, exponent]}: form 0 offsets from `first`, 1 differences, 2 float64 values;
    value = (first + integer) * 10**exponent."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0

    def _ref(self, obj):
        if not isinstance(obj, Packed):
            raise TypeError(f"not JSON: {type(obj).__name__}")
        e, k0, form, size, data = obj.encode()
        at = self.size
        pad = -len(data) % 8
        self.parts.append(data + b"\0" * pad)
        self.size += len(data) + pad
        return {"q": [at, obj.values.size, size, form, k0, e]}

    def pack(self, figures: list) -> str:
        """`figures` (JSON-able, with Packed arrays) as the page's text (`gzip7`)."""
        meta = json.dumps(figures, separators=(",", ":"), default=self._ref).encode()
        head = struct.pack("<I", len(meta)) + meta
        head += b"\0" * (-len(head) % 8)
        return gzip7(head + b"".join(self.parts))
