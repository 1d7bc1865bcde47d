"""The fixed-layout shortcut for candump log-file lines: byte positions by arithmetic.

A `candump -l` log is one layout over and over: `(SSSSSSSSSS.FFFFFF) can0 181#<data>`
with the same time digits and interface on every line. Given the layout of a
chunk's first line, every field's position follows from the line start, so the
general parser's passes that locate ')', '.', ' ' and '#' in every byte (and its
searchsorted calls) are not needed: each row is checked at those fixed positions
and its fields are read as little-endian 8-byte words at byte offsets, decoded
with SWAR arithmetic (8 digits or 16 hex characters per word, a few uint64
operations over the whole column). Rows that do not fit the layout exactly
(other widths, interfaces, RTR, CAN FD, bad text) are left to the general parser,
so results are identical by construction; tests compare both on fuzzed lines.
"""

from __future__ import annotations

import numpy as np

_ONES = 0x0101010101010101
_HI = 0x8080808080808080
_LO7 = 0x7F7F7F7F7F7F7F7F
_NIB = 0x0F0F0F0F0F0F0F0F
_HNIB = 0xF0F0F0F0F0F0F0F0
_ZERO = 0x3030303030303030
CAN_ERR_FLAG = 0x20000000

# _LOWBYTES[k]: mask of the low k bytes of a word; _HIBITS[k]: bit 7 of each of them
_LOWBYTES = np.array([(1 << (8 * k)) - 1 for k in range(9)], np.uint64)
_HIBITS = np.array([_HI & ((1 << (8 * k)) - 1) for k in range(9)], np.uint64)
_POW10 = [10**k for k in range(20)]


def words(arr: np.ndarray) -> np.ndarray:
    """Little-endian uint64 starting at every byte offset of `arr` (a strided view, no copy)."""
    return np.ndarray((arr.size - 7,), dtype="<u8", buffer=arr, strides=(1,))


def _zero_bytes(x: np.ndarray) -> np.ndarray:
    """Bit 7 set in each byte of x that is zero (exact: no borrow between bytes)."""
    return ~(((x & _LO7) + _LO7) | x) & _HI


def _le(x: np.ndarray, limit: int) -> np.ndarray:
    """Bit 7 set in each byte whose value (at most 15) is at most `limit` (< 15)."""
    return ~((x + (15 - limit) * _ONES) << 3) & _HI


def _right_align(x: np.ndarray, k: int, fill: int) -> np.ndarray:
    """The first k bytes of x moved to the top of the word, the low bytes set to `fill`."""
    if k >= 8:
        return x
    shift = 8 * (8 - k)
    return (x << shift) | (fill & ((1 << shift) - 1))


def decimal(w: np.ndarray, pos: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Value of the k decimal digits at pos (k <= 16) and whether all are digits."""
    if k > 8:
        hi, ok_hi = decimal(w, pos, k - 8)
        lo, ok_lo = decimal(w, pos + (k - 8), 8)
        return hi * _POW10[8] + lo, ok_hi & ok_lo
    x = _right_align(w[pos], k, _ZERO)
    lo = x & _NIB
    ok = (_zero_bytes((x & _HNIB) ^ _ZERO) & _le(lo, 9)) == _HI
    v = lo
    v = (v * 10 + (v >> 8)) & 0x00FF00FF00FF00FF
    v = (v * 100 + (v >> 16)) & 0x0000FFFF0000FFFF
    v = (v * 10000 + (v >> 32)) & 0xFFFFFFFF
    return v, ok


def _nibbles(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hex value of each byte of x and bit 7 set in each byte that is a hex digit."""
    lo = x & _NIB
    digit = _zero_bytes((x & _HNIB) ^ _ZERO) & _le(lo, 9)
    upper = x & 0xDFDFDFDFDFDFDFDF  # 'a'-'f' -> 'A'-'F'
    letter = _zero_bytes((upper & _HNIB) ^ 0x4040404040404040) & _le(lo, 6) & ~_zero_bytes(lo)
    nib = lo + ((letter >> 7) * 9)
    return nib, digit | letter


def _pack(nib: np.ndarray) -> np.ndarray:
    """8 nibbles (one per byte, first = most significant) -> their 4 bytes in the low half, in order."""
    y = ((nib & 0x000F000F000F000F) << 4) | ((nib >> 8) & 0x000F000F000F000F)
    y = (y | (y >> 8)) & 0x0000FFFF0000FFFF
    return (y | (y >> 16)) & 0xFFFFFFFF


def hex_id(w: np.ndarray, pos: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Value of the k hex digits at pos (k <= 8) and whether all are hex digits."""
    nib, valid = _nibbles(_right_align(w[pos], k, _ZERO))
    ok = valid == _HI
    b = _pack(nib).astype(np.uint32)  # bytes in reading order: big-endian value
    return b.byteswap(), ok


def hex_data(w: np.ndarray, pos: np.ndarray, n_chars: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, 8) bytes from n_chars (even, <= 16) hex digits at pos, zero padded; all valid."""
    first = np.minimum(n_chars, 8)
    second = n_chars - first
    nib0, v0 = _nibbles(w[pos])
    nib1, v1 = _nibbles(w[pos + 8])
    need0, need1 = _HIBITS[first], _HIBITS[second]
    ok = ((v0 & need0) == need0) & ((v1 & need1) == need1)
    out = (_pack(nib0) | (_pack(nib1) << 32)) & _LOWBYTES[n_chars // 2]
    return out.view(np.uint8).reshape(-1, 8), ok


class Layout:
    """Widths of one line's fields: time digits, interface name."""

    def __init__(self, ni: int, nf: int, name: bytes) -> None:
        self.ni, self.nf, self.name = ni, nf, name

    @classmethod
    def of(cls, line: bytes) -> Layout | None:
        if not line.startswith(b"("):
            return None
        close = line.find(b")")
        dot = line.find(b".", 0, close)
        if close < 0 or dot < 0:
            return None
        ni, nf = dot - 1, close - dot - 1
        sp = line.find(b" ", close + 2)
        if not (1 <= ni <= 16 and 1 <= nf <= 9) or line[close + 1 : close + 2] != b" " or sp < 0:
            return None
        name = line[close + 2 : sp]
        if not 1 <= len(name) <= 32:
            return None
        return cls(ni, nf, name)


def parse(arr: np.ndarray, w: np.ndarray, starts: np.ndarray, ends: np.ndarray, lay: Layout):
    """Columns of the rows that fit `lay` exactly: (t, can_id, flags, dlc, data), fits mask.

    Values of rows that do not fit are garbage; `fits` says which to use.
    """
    from ..frames import FLAG_ERR, FLAG_EXT, FLAG_TX

    s = starts
    last = arr.size - 1
    ni, nf, name = lay.ni, lay.nf, lay.name
    close = s + 1 + ni + 1 + nf
    fits = (
        (arr[s] == 0x28)
        & (arr[s + 1 + ni] == 0x2E)
        & (arr[close] == 0x29)
        & (arr[close + 1] == 0x20)
    )
    sec, ok_s = decimal(w, s + 1, ni)
    frac, ok_f = decimal(w, s + 2 + ni, nf)
    fits &= ok_s & ok_f
    # the interface name and the space after it, 8 bytes at a time
    key = name + b" "
    for i in range(0, len(key), 8):
        piece = key[i : i + 8]
        mask = int(_LOWBYTES[len(piece)])
        fits &= (w[close + 2 + i] & mask) == int.from_bytes(piece, "little")
    p = close + 3 + len(name)  # identifier
    std = arr[p + 3] == 0x23
    ext = ~std & (arr[np.minimum(p + 8, last)] == 0x23)
    fits &= (std | ext) & (p + 3 < ends)
    id11, ok11 = hex_id(w, p, 3)
    if ext.any():
        id29, ok29 = hex_id(w, p, 8)
        fits &= np.where(std, ok11, ok29)
        can_id = np.where(std, id11, id29)
    else:  # 11-bit only (the usual CANopen log): rows without '#' at p+3 already fail
        fits &= ok11
        can_id = id11
    d = np.where(std, p + 4, p + 9)  # data
    e = ends
    tail = (e - d >= 2) & (arr[np.maximum(e - 2, 0)] == 0x20)
    dir_ch = arr[np.maximum(e - 1, 0)]
    tx = tail & (dir_ch == 0x54)
    tail &= tx | (dir_ch == 0x52)
    n_chars = e - d - 2 * tail
    fits &= (d <= e) & (n_chars >= 0) & (n_chars <= 16) & (n_chars % 2 == 0)
    n_chars = np.clip(n_chars, 0, 16) & ~1
    data, ok_d = hex_data(w, d, n_chars)
    fits &= ok_d
    whole = (sec * _POW10[nf] + frac).astype(np.int64) if ni + nf <= 18 else None
    if whole is not None:
        t = np.where(whole < 2**53, whole / 10.0**nf, sec.astype(np.int64) + frac / 10.0**nf)
    else:
        t = sec.astype(np.int64) + frac / 10.0**nf
    flags = np.zeros(s.size, np.uint8)
    err = ext & ((can_id & CAN_ERR_FLAG) != 0)
    flags[ext & ~err] |= FLAG_EXT
    flags[err] |= FLAG_ERR
    flags[tx] |= FLAG_TX
    can_id = can_id & np.uint32(0x1FFFFFFF)
    return (t, can_id, flags, (n_chars // 2).astype(np.uint8), data), fits
