"""Numbers as text for a whole column at once, byte for byte what Python prints.

The text output shows PDO signal values as `f"{value:.6g}"` (floats) or `str()`
(integers, booleans). Hundreds of thousands of values per second are too many
for a Python call each, so a column is formatted as a NUL-padded byte matrix
(the text writer drops the NULs). Floats are rounded in numpy; the few whose
rounding is in doubt (a near tie), which need an exponent, or which are not
finite are formatted by Python and written in, so the text cannot differ.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.runtime import speedups

_PAD = 0
_ZERO = 48


def int_text(values: np.ndarray) -> np.ndarray:
    """(n, w) NUL-padded decimal text of integers (`str(int(v))`)."""
    if values.dtype.kind == "u" and values.size and int(values.max()) >= 1 << 63:
        return _python_text(values, str)  # beyond int64
    return bytecols.decimal(values.astype(np.int64))


def bool_text(values: np.ndarray) -> np.ndarray:
    """(n, 5) NUL-padded `True` / `False`."""
    table = np.array([list(b"False"), list(b"True\0")], np.uint8)
    return table[values.astype(bool).astype(np.intp)]


def g6_text(values: np.ndarray) -> np.ndarray:
    """(n, w) NUL-padded `f"{v:.6g}"` of float64 values."""
    x = values.astype(np.float64, copy=False)
    n = x.size
    compiled = getattr(speedups.C, "g6_text", None)
    if compiled is not None:  # the same rounding and doubt, one pass
        out = np.zeros((n, 24), np.uint8)
        width = compiled(np.ascontiguousarray(x), out)
        return out[:, : max(width, 1)]
    out = np.zeros((n, 13), np.uint8)  # sign, "0.", up to 3 more zeros, 6 digits, spare
    ax = np.abs(x)
    finite = np.isfinite(x)
    zero = x == 0
    usable = finite & ~zero
    ax = np.where(usable, ax, 1.0)
    e = np.floor(np.log10(ax)).astype(np.int64)
    fast = usable & (e >= -4) & (e <= 5)
    e = np.where(fast, e, 0)
    with np.errstate(over="ignore", invalid="ignore"):  # rows past 1e303: not fast anyway
        m = ax * (10.0 ** (5 - e))  # exact power of ten: one rounding, error far below 1e-6
        r = np.rint(m)
        frac = m - np.floor(m)
    fast &= (m >= 1e5) & (r < 1e6) & (np.abs(frac - 0.5) > 1e-6)
    r = np.where(fast, r, 1e5).astype(np.int64)
    neg = np.signbit(x)
    out[:, 0] = np.where(neg, ord("-"), _PAD)
    digits = bytecols.digits(r, 6)
    # trailing zero digits, never counting the integer part
    nz = digits != _ZERO
    last = 5 - np.argmax(nz[:, ::-1], axis=1)  # index of the last non-zero digit
    for ex in np.unique(e[fast]).tolist():
        rows = np.flatnonzero(fast & (e == ex))
        d = digits[rows]
        keep_to = last[rows]  # digits after keep_to are trailing zeros
        block = np.zeros((rows.size, 12), np.uint8)
        if ex >= 0:
            block[:, : ex + 1] = d[:, : ex + 1]
            has_frac = keep_to > ex
            block[:, ex + 1] = np.where(has_frac, ord("."), _PAD)
            tail = d[:, ex + 1 :]
            cols = np.arange(ex + 1, 6)[None, :]
            block[:, ex + 2 : 7] = np.where(cols <= keep_to[:, None], tail, _PAD)
        else:
            lead = -ex - 1  # zeros between the point and the first digit
            block[:, 0] = _ZERO
            block[:, 1] = ord(".")
            block[:, 2 : 2 + lead] = _ZERO
            cols = np.arange(6)[None, :]
            block[:, 2 + lead : 8 + lead] = np.where(cols <= keep_to[:, None], d, _PAD)
        out[rows, 1:] = block
    zrows = np.flatnonzero(zero)
    out[zrows, 1] = _ZERO
    slow = np.flatnonzero(~fast & ~zero)
    if slow.size:
        texts = [f"{v:.6g}".encode() for v in x[slow].tolist()]
        width = max(13, max(len(t) for t in texts))
        if width > 13:
            out = np.concatenate([out, np.zeros((n, width - 13), np.uint8)], axis=1)
        for i, t in zip(slow.tolist(), texts, strict=True):
            out[i] = _PAD
            out[i, : len(t)] = np.frombuffer(t, np.uint8)
    return out


def value_text(values: np.ndarray) -> np.ndarray:
    """NUL-padded text of a signal column as `_fmt_signal` prints each value."""
    kind = values.dtype.kind
    if kind == "f":
        return g6_text(values)
    if kind == "b":
        return bool_text(values)
    if kind in "iu":
        return int_text(values)

    return _python_text(values, scalar_text)


def scalar_text(v) -> str:
    """One signal value as the text output prints it (the od table's PDO values too)."""
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def _python_text(values: np.ndarray, fmt) -> np.ndarray:
    texts = [fmt(v).encode() for v in values.tolist()]
    width = max((len(t) for t in texts), default=1)
    out = np.zeros((len(texts), width), np.uint8)
    for i, t in enumerate(texts):
        out[i, : len(t)] = np.frombuffer(t, np.uint8)
    return out
