"""candump logs: `-l`/`-L` log-file lines and the screen format, with or without times.

Log-file lines `(1700000000.123456) can0 181#0102 [R|T]` are parsed in bulk over
the raw bytes of a chunk: by the compiled helper's `candump_lines` when it is
built, else by `_bulk_log_lines` (numpy). Both take exactly the same lines, with
the same values (python-can's CanutilsLogReader makes one Message per frame and
converts hex byte by byte: about 140k frames/s; these paths run in the millions).
Every line they leave, and every screen format line (`  can0  181   [2]  01 02`,
optionally after `(time)` or a bare `1700000000.123456`, with `-x`'s `TX B -`
direction and CAN FD marks), goes through the line parser below, which is also
where problems are reported. The `-x` direction is the frame's FLAG_TX, as the ` T`
that `-l -x` writes is. Written (`simulate --to`, `live --record`) as `candump -l` writes it.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from typing import BinaryIO

import numpy as np

from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
    channel_index,
    concat,
    set_row,
)
from cananalyze.formats.registry import LogFormat, ReadContext, register
from cananalyze.runtime import speedups

CHUNK = 1 << 22  # bytes per bulk parse (about 90k log-file lines)
MAX_LINE = 1 << 24  # a line longer than this (no newline in 16 MiB) is skipped
PAD = 128  # zero bytes after a chunk, so the numpy parser's windows never run off its end
CAN_ERR_FLAG = 0x20000000

_HEX = np.full(256, 255, np.uint8)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    _HEX[_c] = 10 + _i
_DIGIT = np.full(256, 255, np.uint8)
for _i, _c in enumerate(b"0123456789"):
    _DIGIT[_c] = _i

_LOG_RE = re.compile(
    rb"^\s*\((?P<t>[^)]*)\)\s+(?P<ch>\S+)\s+(?P<id>[0-9A-Fa-f]+)#(?P<rest>\S*)(?:\s+(?P<dir>[RT]))?\s*$"
)
# The screen format (can-utils candump.c, lib.c snprintf_long_canframe):
#   " (1700000000.123456)  can0  TX B -  123  [12]  11 22 ..."
# a time in parentheses (-ta/-td/-tz/-tA) or none, or a bare number (some loggers print
# `1768357807.264241 can0 601 [8] 2B ...`); then the interface; with -x the direction and
# the CAN FD BRS and ESI marks ("TX"/"RX", then "B"/"-" and "E"/"-"); the identifier;
# the length, one digit for classic CAN ("[8]"), two for CAN FD ("[08]", "[12]").
_SCREEN_RE = re.compile(
    rb"^\s*(?:\((?P<t>[^)]*)\)\s+|(?P<bare>\d+\.\d+)\s+)?(?P<ch>\S+)\s+"
    rb"(?:(?P<dir>[RT]X)\s+(?P<brs>[B-])\s(?P<esi>[E-])\s+)?"
    rb"(?P<id>[0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})\s+"
    rb"(?:(?P<fl>[BEI-]{3})\s+)?\[(?P<len>\d+)\]\s*(?P<rest>.*)$"
)
_HEXBYTE = re.compile(rb"^[0-9A-Fa-f]{2}$")


class _Channels:
    """Interface names to stable small integers across the batches of one log."""

    def __init__(self) -> None:
        self.names: list[str] = []
        self.index: dict[str, int] = {}

    def get(self, name: str) -> int:
        return channel_index(self.names, self.index, name)

    def tuple(self) -> tuple[str, ...]:
        return tuple(self.names)


def _first_after(positions: np.ndarray, starts: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Position of the first occurrence at or after each start, or `limit` if none before it."""
    if positions.size == 0:
        return limit.copy()
    k = np.searchsorted(positions, starts)
    found = np.where(k < positions.size, positions[np.minimum(k, positions.size - 1)], limit)
    return np.minimum(found, limit)


def _window(arr: np.ndarray, start: np.ndarray, width: int) -> np.ndarray:
    """(n, width) bytes from each start: rows of a strided view, no index matrix.

    `arr` is padded by the caller (PAD bytes past the end), so every window fits.
    """
    return np.lib.stride_tricks.sliding_window_view(arr, width)[start]


def _groups(keys: np.ndarray):
    """(key, rows) per distinct key; rows is None when every row has the one key (the usual case)."""
    if keys.size and (keys == keys[0]).all():
        yield int(keys[0]), None
        return
    for key in np.unique(keys):
        yield int(key), np.flatnonzero(keys == key)


def _parse_hex(arr: np.ndarray, start: np.ndarray, length: np.ndarray, width: int):
    """Value of the hex field [start, start+length) per row; second result: all digits valid.

    Rows are grouped by field length (a log has one or two: 3 and 8 digits), and
    each group is a fixed-width gather and a dot product with powers of 16
    (in float64, exact for 8 digits, where numpy uses BLAS).
    """
    val = np.zeros(start.size, np.uint64)
    ok = np.zeros(start.size, bool)
    for n_digits, rows in _groups(length):
        if n_digits <= 0 or n_digits > width:
            continue
        sel = slice(None) if rows is None else rows
        digits = _HEX[_window(arr, start[sel], n_digits)]
        ok[sel] = np.all(digits != 255, axis=1)
        powers = 16.0 ** np.arange(n_digits - 1, -1, -1)
        val[sel] = (digits.astype(np.float64) @ powers).astype(np.uint64)
    return val, ok


def _parse_time(arr: np.ndarray, start: np.ndarray, end: np.ndarray, dots: np.ndarray):
    """Seconds from 'digits.digits' in [start, end); second result: well formed.

    1-18 integer and 1-12 fraction digits, as the C parser takes them; other times
    (candump writes none) are the line parser's. Grouped by (integer digits,
    fraction digits): usually one group per chunk. All digits are read as one
    integer and divided once by 10**fraction digits, which is exactly float(text)
    while the integer is below 2**53.
    """
    dot = _first_after(dots, start, end)
    n_int = dot - start
    n_frac = np.where(dot < end, end - dot - 1, 0)
    t = np.zeros(start.size, np.float64)
    ok = np.zeros(start.size, bool)
    keys = n_int * 64 + n_frac
    for key, rows in _groups(keys):
        ni, nf = key // 64, key % 64
        if ni < 1 or ni > 18 or nf < 1 or nf > 12:
            continue
        sel = slice(None) if rows is None else rows
        digits = _DIGIT[_window(arr, start[sel], ni + 1 + nf)]
        if ni + nf <= 15:
            # one float64 dot product (BLAS), the '.' column weighted 0: exact below 1e15
            weights = np.zeros(ni + 1 + nf)
            weights[:ni] = 10.0 ** np.arange(ni + nf - 1, nf - 1, -1)
            weights[ni + 1 :] = 10.0 ** np.arange(nf - 1, -1, -1)
            ok[sel] = np.count_nonzero(digits == 255, axis=1) == 1  # only the '.'
            t[sel] = (digits.astype(np.float64) @ weights) / 10.0**nf
            continue
        fd = digits[:, ni + 1 :]
        ok[sel] = np.all(digits[:, :ni] != 255, axis=1) & np.all(fd != 255, axis=1)
        sec = digits[:, :ni].astype(np.int64) @ (10 ** np.arange(ni - 1, -1, -1, dtype=np.int64))
        frac = fd.astype(np.int64) @ (10 ** np.arange(nf - 1, -1, -1, dtype=np.int64))
        if ni + nf <= 18:
            whole = sec * 10**nf + frac
            t[sel] = np.where(whole < 2**53, whole / 10.0**nf, sec + frac / 10.0**nf)
        else:
            t[sel] = sec + frac / 10.0**nf
    return t, ok


def _bulk_log_lines(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray, chans: _Channels):
    """Parse `(t) iface id#data [dir]` lines as columns: the path without the C helper.

    Takes exactly the lines `_speedups.candump_lines` takes, with the same values
    (tests/test_speedups.py), so the line parser sees the same lines either way.
    Returns (batch columns for the good rows, mask of rows the line parser must see).
    """
    n = starts.size
    good = arr[np.minimum(starts, arr.size - 1)] == ord("(")
    close = _first_after(np.flatnonzero(arr == ord(")")), starts, ends)
    spaces = np.flatnonzero(arr == ord(" "))
    hashes = np.flatnonzero(arr == ord("#"))
    t, t_ok = _parse_time(arr, starts + 1, close, np.flatnonzero(arr == ord(".")))
    good &= t_ok & (close < ends) & (arr[np.minimum(close + 1, arr.size - 1)] == ord(" "))
    ch_start = close + 2
    ch_end = _first_after(spaces, ch_start, ends)
    good &= ch_end > ch_start  # an interface name
    id_start = ch_end + 1
    hash_pos = _first_after(hashes, id_start, ends)
    id_len = hash_pos - id_start
    good &= (hash_pos < ends) & ((id_len == 3) | (id_len == 8))
    can_id, id_ok = _parse_hex(arr, id_start, id_len, 8)
    good &= id_ok & ((id_len == 8) | (can_id <= 0x7FF))  # 3 digits above 7FF: see _parse_line
    d_start = hash_pos + 1
    d_end = _first_after(spaces, d_start, ends)
    first = arr[np.minimum(d_start, arr.size - 1)]
    rtr = (first == ord("R")) & (d_start < ends)
    fd = (first == ord("#")) & (d_start < ends)
    d_len2 = d_end - d_start
    good &= ~fd & ((d_len2 % 2 == 0) | rtr) & (d_len2 <= 16)
    good &= ~(rtr & (d_len2 > 2))
    # direction flag written by python-can: " R" (received) or " T" (sent)
    tail = d_end < ends
    dir_ch = arr[np.minimum(d_end + 1, arr.size - 1)]
    tx = tail & (dir_ch == ord("T"))
    good &= ~tail | (((dir_ch == ord("R")) | tx) & (ends - d_end == 2))
    win = _HEX[_window(arr, d_start, 16)].reshape(n, 8, 2)
    nbytes = np.where(rtr, 0, d_len2 // 2)
    inside = np.arange(8) < nbytes[:, None]
    valid = (win[:, :, 0] != 255) & (win[:, :, 1] != 255)
    good &= np.all(valid | ~inside, axis=1)
    data = np.where(inside, (win[:, :, 0] << 4) | (win[:, :, 1] & 0x0F), 0).astype(np.uint8)
    rtr_len = np.where(d_len2 == 2, _DIGIT[arr[np.minimum(d_start + 1, arr.size - 1)]], 0)
    good &= ~rtr | (rtr_len <= 8)
    dlc = np.where(rtr, rtr_len, nbytes).astype(np.uint8)

    flags = np.zeros(n, np.uint8)
    err = (id_len == 8) & ((can_id & np.uint64(CAN_ERR_FLAG)) != 0)
    flags[(id_len == 8) & ~err] |= FLAG_EXT
    flags[err] |= FLAG_ERR
    flags[rtr] |= FLAG_RTR
    flags[tx] |= FLAG_TX
    can_id = (can_id & np.uint64(0x1FFFFFFF)).astype(np.uint32)

    # interface names: the usual log has one; compare every row with the first
    channel = np.zeros(n, np.uint16)
    rows = np.flatnonzero(good)
    if rows.size:
        ch_len = ch_end - ch_start
        r0 = rows[0]
        width = int(ch_len[r0])
        first_name = arr[ch_start[r0] : ch_start[r0] + width]
        # clip the window starts: a long first name would run past the padding on other
        # rows (those rows have another length, so they compare unequal either way)
        starts = np.clip(ch_start, 0, arr.size - width)
        same = (ch_len == width) & np.all(_window(arr, starts, width) == first_name, axis=1)
        channel[:] = chans.get(first_name.tobytes().decode("latin-1"))
        for r in rows[~same[rows]]:  # several interfaces: rare, per distinct row
            channel[r] = chans.get(arr[ch_start[r] : ch_end[r]].tobytes().decode("latin-1"))
    return (t, can_id, flags, dlc, data, channel), ~good


class _Bounds:
    """Line start and end buffers reused chunk after chunk (only read within a round)."""

    def __init__(self) -> None:
        self.starts = self.ends = np.empty(0, np.int64)

    def get(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        if self.starts.size < n:
            self.starts, self.ends = np.empty(n, np.int64), np.empty(n, np.int64)
        return self.starts, self.ends


def _c_lines(C, text, chans: _Channels, bounds: _Bounds):
    """The compiled parser over a chunk: (starts, ends, columns, mask of lines it left).

    Interfaces are numbered in the order their first parsed line comes, as
    `_bulk_log_lines` numbers them: the C loop knows the names seen so far, and a
    line on a new one (status 1) gets it named here, then the lines still waiting
    are parsed again with it, a round per new interface.
    """
    size = len(text)
    # room for lines of 24 bytes on average (candump's are 30-60): one pass over the
    # chunk instead of counting first; the count is only needed when lines are shorter
    starts, ends = bounds.get(size // 24 + 64)
    n = C.split_lines(text, starts, ends, False)
    if n < 0:
        starts, ends = bounds.get(C.count_lines(text))
        n = C.split_lines(text, starts, ends, False)
    starts, ends = starts[:n], ends[:n]
    cols = (
        np.empty(n, np.float64),  # t
        np.empty(n, np.uint32),  # can_id
        np.empty(n, np.uint8),  # flags
        np.empty(n, np.uint8),  # dlc
        np.empty((n, 8), np.uint8),  # data
        np.empty(n, np.uint16),  # channel
    )
    status = np.empty(n, np.uint8)
    C.candump_lines(text, starts, ends, _names(chans), *cols, status)
    rows = np.flatnonzero(status == 1)
    for _ in range(8):
        if rows.size == 0:
            break
        chans.get(_name_at(text, starts[rows[0]], ends[rows[0]]))
        part = tuple(np.empty_like(c[rows]) for c in cols)
        part_status = np.empty(rows.size, np.uint8)
        C.candump_lines(text, starts[rows], ends[rows], _names(chans), *part, part_status)
        for full, got in zip(cols, part, strict=True):
            full[rows] = got
        rows = rows[part_status == 1]
    for r in rows.tolist():  # many interfaces in one chunk: the rest one by one
        cols[5][r] = chans.get(_name_at(text, starts[r], ends[r]))
    return starts, ends, cols, status == 2


def _names(chans: _Channels) -> tuple[bytes, ...]:
    return tuple(name.encode("latin-1") for name in chans.names)


def _name_at(text, start: int, end: int) -> str:
    """The interface of a line the C parser took: after `(time) `, up to the next space."""
    line = bytes(text[start:end])
    at = line.index(b")") + 2
    return line[at : line.index(b" ", at)].decode("latin-1")


def _parse_time_text(text: bytes) -> float | None:
    s = text.decode("latin-1").strip()
    try:
        t = float(s)
    except ValueError:
        pass
    else:
        return t if -1e300 < t < 1e300 else None  # "nan", "inf", "1e999" are no times
    try:  # candump -tA: (2023-11-09 10:11:12.123456)
        return datetime.fromisoformat(s).timestamp()
    except (ValueError, OverflowError, OSError):  # year 1 in local time, out-of-range dates
        return None


def _too_wide(ident: bytes) -> str:
    return f"identifier {ident.decode('latin-1')!r} is above 7FF, the largest 11-bit (3-digit) one"


def _parse_line(line: bytes):
    """One candump line of any variant -> (t, channel, can_id, flags, payload) or an error text."""
    m = _LOG_RE.match(line)
    if m:
        t = _parse_time_text(m["t"])
        if t is None:
            return f"bad timestamp {m['t'].decode('latin-1')!r}"
        ident = m["id"]
        if len(ident) not in (3, 8):
            return f"identifier {ident.decode('latin-1')!r} is neither 3 (11-bit) nor 8 (29-bit) hex digits"
        can_id = int(ident, 16)
        if len(ident) == 3 and can_id > 0x7FF:
            return _too_wide(ident)
        flags = FLAG_TX if m["dir"] == b"T" else 0
        if len(ident) == 8:
            if can_id & CAN_ERR_FLAG:
                flags |= FLAG_ERR
            else:
                flags |= FLAG_EXT
            can_id &= 0x1FFFFFFF
        rest = m["rest"]
        if rest.startswith(b"#"):  # CAN FD: ##<flags nibble><data>
            if len(rest) < 2 or rest[1:2] not in b"0123456789ABCDEFabcdef":
                return "CAN FD frame without its flags digit after '##'"
            fd_flags = int(rest[1:2], 16)
            flags |= FLAG_FD | (FLAG_BRS if fd_flags & 1 else 0) | (FLAG_ESI if fd_flags & 2 else 0)
            rest = rest[2:]
        elif rest[:1] in (b"R", b"r"):
            flags |= FLAG_RTR
            n = rest[1:]
            if n and not (n.isdigit() and int(n) <= 8):
                return f"bad remote-frame length {n.decode('latin-1')!r}"
            return t, m["ch"], can_id, flags, bytes(int(n) if n else 0)
        if not all(c in b"0123456789ABCDEFabcdef" for c in rest):
            return f"invalid hex in data {rest.decode('latin-1')!r}"
        if len(rest) % 2:
            return f"odd number of hex digits in data {rest.decode('latin-1')!r}"
        payload = bytes.fromhex(rest.decode("latin-1"))
        if len(payload) > (64 if flags & FLAG_FD else 8):
            return f"{len(payload)} data bytes is more than a CAN frame carries"
        return t, m["ch"], can_id, flags, payload
    m = _SCREEN_RE.match(line)
    if m:
        t = None
        stamp = m["t"] if m["t"] is not None else m["bare"]
        if stamp is not None:
            t = _parse_time_text(stamp)
            if t is None:
                return f"bad timestamp {stamp.decode('latin-1')!r}"
        ident = m["id"]
        can_id = int(ident, 16)
        if len(ident) == 3 and can_id > 0x7FF:
            return _too_wide(ident)
        flags = FLAG_EXT if len(ident) == 8 else 0
        if len(ident) == 8 and can_id & CAN_ERR_FLAG:
            flags = FLAG_ERR
            can_id &= 0x1FFFFFFF
        if m["dir"] == b"TX":  # candump -x: sent by this host's socket
            flags |= FLAG_TX
        length = int(m["len"])
        rest = m["rest"].split()
        if rest[:2] == [b"remote", b"request"]:
            return t, m["ch"], can_id, flags | FLAG_RTR, bytes(length)
        fields = rest[:length]
        if length > 64 or len(fields) < length or not all(_HEXBYTE.match(f) for f in fields):
            return f"expected {length} hex data bytes after [{length}]"
        # CAN FD: candump prints its length with two digits ([08], [12]); -x marks BRS, ESI
        if length > 8 or len(m["len"]) == 2 or m["brs"] == b"B" or m["esi"] == b"E":
            flags |= FLAG_FD
            if m["brs"] == b"B":
                flags |= FLAG_BRS
            if m["esi"] == b"E":
                flags |= FLAG_ESI
        # anything after the data bytes (a user's comment) is ignored
        return t, m["ch"], can_id, flags, bytes(int(f, 16) for f in fields)
    return "not a candump line"


SNIFF_LINES = 40  # candump lines must be half of this many lines from the first one on


def _is_frame_line(line: bytes) -> bool:
    return bool(_LOG_RE.match(line) or _SCREEN_RE.match(line))


def sniff(head: bytes) -> bool:
    """Half of the SNIFF_LINES non-blank lines from the first candump line on are candump
    lines. The lines before it are a header (notes, the capture's commands) or a first
    line that is cut or long: only the lines after the first matter, as many as the
    head holds (the source facade reads on past a long header until a format claims it).
    """
    raw = head.splitlines()
    lines = [ln for ln in raw[1:] if ln.strip()]  # the first line may be cut or a command
    if not lines:
        lines = [ln for ln in raw if ln.strip()]
    for i, line in enumerate(lines):
        if _is_frame_line(line):
            window = lines[i : i + SNIFF_LINES]
            hits = 1 + sum(1 for ln in window[1:] if _is_frame_line(ln))
            return hits >= max(1, len(window) // 2)
    return False


class _Builder:
    """Collects line-parser rows (rare path) as lists, then makes a batch."""

    def __init__(self) -> None:
        self.rows: list[tuple] = []

    def batch(self, chans: _Channels) -> FrameBatch:
        rows = self.rows
        b = FrameBatch.allocate(len(rows))
        for i, (line_no, t, ch, can_id, flags, payload) in enumerate(rows):
            set_row(b, i, t, can_id, flags, payload, chans.get(ch.decode("latin-1")), line_no)
        self.rows = []
        return b


class _Chunks:
    """The log read CHUNK bytes at a time into one reused buffer, after the partial line
    the previous chunk ended with, which stays at the buffer's start (moved there, never
    also held as bytes): no fresh 4 MiB per chunk and no copy joining it to the chunk.
    A line longer than a chunk grows the buffer in place, up to MAX_LINE."""

    def __init__(self, stream: BinaryIO) -> None:
        self.stream = stream
        self.readinto = getattr(stream, "readinto", None)
        self.buf = bytearray(CHUNK)
        self.carry = 0  # bytes of the partial line at buf[:carry]

    def fill(self) -> int:
        """Read the next chunk after the carried line: the bytes read (0 at the end)."""
        need = self.carry + CHUNK
        if len(self.buf) < need:  # a line longer than a chunk: grow in place
            self.buf += bytes(need - len(self.buf))
        lo = self.carry
        if self.readinto is None:
            block = self.stream.read(CHUNK)
            self.buf[lo : lo + len(block)] = block
            return len(block)
        with memoryview(self.buf) as view:
            got = 0
            while got < CHUNK:  # the chunk bounds of read(CHUNK), even from short reads
                n = self.readinto(view[lo + got : lo + CHUNK]) or 0
                if n == 0:
                    break
                got += n
        return got

    def keep(self, start: int, end: int) -> None:
        """Carry buf[start:end] (the partial line after the last newline) to the next chunk."""
        if start:
            self.buf[: end - start] = self.buf[start:end]
        self.carry = end - start

    def drop(self) -> None:
        """Forget the carried line (skipped as too long) and shrink back to one chunk."""
        self.carry = 0
        del self.buf[CHUNK:]


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "candump"
    chans = _Channels()
    line_base = 0  # lines before the current chunk
    chunks = _Chunks(stream)
    bounds = _Bounds()
    absolute = None
    pending: list[FrameBatch] = []
    pending_rows = 0
    eof = False
    skipping = False  # inside a line too long to keep: drop bytes up to its newline
    while not eof:
        got = chunks.fill()
        eof = got == 0
        buf = chunks.buf
        lo = 0  # this round's text is buf[lo:lo + size]
        hi = chunks.carry + got
        if skipping:  # nothing is carried then
            if eof:
                break
            nl = buf.find(b"\n", 0, hi)
            if nl < 0:
                continue
            lo, skipping = nl + 1, False
            line_base += 1
        if not eof:
            last_nl = buf.rfind(b"\n", lo, hi)
            if last_nl < 0:
                chunks.keep(lo, hi)
                if chunks.carry > MAX_LINE:
                    ctx.problems.add(
                        ctx.source, f"line {line_base + 1}", "line longer than 16 MiB, skipped"
                    )
                    chunks.drop()
                    skipping = True
                continue
            size = last_nl + 1 - lo
        elif not chunks.carry:
            break
        else:
            size = chunks.carry
        C = speedups.C
        kept = None  # the lines the parse saw, when blank ones were left out of it
        if C is not None:
            text = memoryview(buf)[lo : lo + size]
            starts, ends, cols, slow = _c_lines(C, text, chans, bounds)
            n_lines = starts.size
        else:
            # the text goes straight into one padded array: a single copy of the bytes
            text = arr = np.empty(size + PAD, np.uint8)
            arr[:size] = np.frombuffer(buf, np.uint8, count=size, offset=lo)
            arr[size:] = 0
            nl = np.flatnonzero(arr[:size] == 10)
            if nl.size == 0 or nl[-1] != size - 1:
                nl = np.append(nl, size)
            starts = np.empty(nl.size, np.int64)
            starts[0] = 0
            starts[1:] = nl[:-1] + 1
            ends = nl.astype(np.int64)
            # strip '\r' before '\n'
            cr = (ends > starts) & (arr[np.maximum(ends - 1, 0)] == 13)
            ends = ends - cr
            n_lines = starts.size
            if not (ends > starts).all():  # empty lines: not parsed, a column row each
                kept = np.flatnonzero(ends > starts)
                starts, ends = starts[kept], ends[kept]
            cols, slow = _bulk_log_lines(arr, starts, ends, chans)
        line_no = line_base + 1 + (np.arange(n_lines, dtype=np.int64) if kept is None else kept)
        line_base += n_lines
        nonblank = ends > starts
        slow &= nonblank
        good = ~slow & nonblank
        parts: list[FrameBatch] = []
        if good.size and good.all():  # the usual chunk: every line a frame, no copies
            parts.append(FrameBatch(*cols, line_no))
            if absolute is None:
                absolute = bool(cols[0][0] > 1e8)
        elif good.any():
            t, can_id, flags, dlc, data, channel = cols
            g = np.flatnonzero(good)
            parts.append(
                FrameBatch(t[g], can_id[g], flags[g], dlc[g], data[g], channel[g], line_no[g])
            )
            if absolute is None:
                absolute = bool(t[g[0]] > 1e8)
        if slow.any():
            builder = _Builder()
            for r in np.flatnonzero(slow):
                raw = bytes(text[starts[r] : ends[r]])
                parsed = _parse_line(raw)
                if isinstance(parsed, str):
                    if r == 0 and line_no[r] == 1 and raw.lstrip().startswith(b"candump"):
                        continue  # the shell command some captures begin with
                    ctx.problems.add(ctx.source, f"line {line_no[r]}", f"{parsed}: {raw[:80]!r}")
                    continue
                t, ch, can_id, flags, payload = parsed
                if t is None:
                    t = 0.0  # screen output without -t: order is all there is
                elif absolute is None:
                    absolute = t > 1e8
                builder.rows.append((int(line_no[r]), t, ch, can_id, flags, payload))
            if builder.rows:
                parts.append(builder.batch(chans))
        text = None  # release the buffer's view: the carry is moved next
        chunks.keep(lo + size, hi)
        if len(parts) == 2:  # keep file order when both paths produced rows
            merged = concat(parts)
            order = np.argsort(merged.line, kind="stable")
            parts = [merged.take(order)]
        for p in parts:
            p.channels = chans.tuple()
            pending.append(p)
            pending_rows += len(p)
        if pending_rows >= ctx.batch_size or (eof and pending):
            out = concat(pending) if len(pending) > 1 else pending[0]
            out.channels = chans.tuple()
            pending, pending_rows = [], 0
            ctx.frames += len(out)
            ctx.absolute_time = bool(absolute)
            ctx.extras["timestamps"] = absolute is not None
            yield out
    if pending:
        out = concat(pending)
        out.channels = chans.tuple()
        ctx.frames += len(out)
        yield out
    ctx.absolute_time = bool(absolute)
    ctx.extras["timestamps"] = absolute is not None


# ---- writing: candump -l lines, in bulk (benchmark logs run to 10M lines) ---------------------

_HEX2 = np.array([f"{i:02X}" for i in range(256)])


def candump_lines(batch: FrameBatch) -> list[str]:
    """`(t) ch id#data` lines of a batch (candump -l format)."""
    n = len(batch)
    if n == 0:
        return []
    t = np.char.mod("%.6f", batch.t)
    ids = batch.can_id
    ext = (batch.flags & (FLAG_EXT | FLAG_ERR)) != 0
    id_txt = np.where(
        ext,
        np.char.mod(
            "%08X", ids | np.where((batch.flags & FLAG_ERR) != 0, 0x20000000, 0).astype(np.uint32)
        ),
        np.char.mod("%03X", ids),
    )
    out = []
    hexed = _HEX2[batch.data]
    chans = batch.channels or ("can0",)
    for i in range(n):
        fl = int(batch.flags[i])
        dlc = int(batch.dlc[i])
        if fl & FLAG_RTR:
            body = "R" if dlc == 0 else f"R{dlc}"
        elif fl & FLAG_FD:
            payload = batch.payload(i)
            body = f"#{(1 if fl & 0x10 else 0) | (2 if fl & 0x20 else 0):X}" + payload.hex().upper()
        else:
            body = "".join(hexed[i, :dlc])
        ch = chans[int(batch.channel[i])] if int(batch.channel[i]) < len(chans) else "can0"
        line = f"({t[i]}) {ch} {id_txt[i]}#{body}"
        if fl & FLAG_TX:
            line += " T"
        out.append(line)
    return out


def _digits(values: np.ndarray, width: int) -> np.ndarray:
    """(n, width) ASCII digits of non-negative integers, zero padded."""
    out = np.empty((values.size, width), np.uint8)
    v = values.astype(np.int64).copy()
    for j in range(width - 1, -1, -1):
        out[:, j] = 48 + v % 10
        v //= 10
    return out


_HEXCHARS = np.frombuffer(b"0123456789ABCDEF", np.uint8)
_PAD = 0


def candump_bytes(batch: FrameBatch) -> bytes:
    """candump -l text of a batch of classic frames, built as one byte matrix.

    Every line is laid out at fixed width with pad bytes, then the pads are
    dropped in one boolean selection: no Python per frame.
    """
    n = len(batch)
    if n == 0:
        return b""
    chans = batch.channels or ("can0",)
    if len(chans) > 1 or (batch.flags & (FLAG_FD | FLAG_ERR)).any() or (batch.t < 0).any():
        return ("\n".join(candump_lines(batch)) + "\n").encode("ascii")
    us = np.round(batch.t * 1e6).astype(np.int64)
    sec, frac = np.divmod(us, 1_000_000)
    sec_w = max(1, len(str(int(sec.max()))))
    ch = chans[0].encode("ascii")
    ext = (batch.flags & FLAG_EXT) != 0
    rtr = (batch.flags & FLAG_RTR) != 0
    tx = (batch.flags & FLAG_TX) != 0
    parts = [
        np.full((n, 1), ord("("), np.uint8),
        _digits(sec, sec_w),
        np.full((n, 1), ord("."), np.uint8),
        _digits(frac, 6),
        np.frombuffer(b") " + ch + b" ", np.uint8)[None, :].repeat(n, 0),
    ]
    ident = np.empty((n, 8), np.uint8)
    for j in range(8):
        ident[:, j] = _HEXCHARS[(batch.can_id >> (4 * (7 - j))) & 0xF]
    ident[~ext, :5] = _PAD  # 3-digit standard identifiers
    parts.append(ident)
    parts.append(np.full((n, 1), ord("#"), np.uint8))
    data = np.empty((n, 16), np.uint8)
    data[:, 0::2] = _HEXCHARS[batch.data >> 4]
    data[:, 1::2] = _HEXCHARS[batch.data & 0xF]
    data[np.arange(16) >= 2 * batch.dlc[:, None].astype(np.int64)] = _PAD
    data[rtr] = _PAD
    data[rtr, 0] = ord("R")
    rtr_len = rtr & (batch.dlc > 0)
    data[rtr_len, 1] = 48 + batch.dlc[rtr_len]
    parts.append(data)
    tail = np.full((n, 3), _PAD, np.uint8)
    tail[tx, 0] = ord(" ")
    tail[tx, 1] = ord("T")
    tail[:, 2] = ord("\n")
    parts.append(tail)
    mat = np.concatenate(parts, axis=1)
    return mat[mat != _PAD].tobytes()


class CandumpWriter:
    """Appends batches to a candump -l file."""

    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb")  # noqa: SIM115 - closed in close()

    def write(self, batch: FrameBatch) -> None:
        if len(batch):
            self._file.write(candump_bytes(batch))

    def flush(self) -> None:
        if self._file is not None:
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


register(
    LogFormat(
        name="candump",
        description="SocketCAN candump (-l/-L log file, or screen output)",
        sniff=sniff,
        read=read,
        suffixes=(".log", ".candump", ".txt"),
        priority=30,
        write_suffix=".log",
        writer=CandumpWriter,
    )
)
