"""Vector ASC text logs: classic and CAN FD frames, remote and error frames.

python-can's ASCReader builds one Message per frame and silently drops lines it
cannot parse; this reader tokenises each line straight into a RowSink (columns),
and reports malformed frame lines with their line number. It follows python-can
for what each field means (channel numbers, DLC codes, FD columns), and reuses
its locale-tolerant header date parser.

Time: with ``date`` in the header and ``timestamps absolute`` the frame times
are offsets from that date (local time, as Vector writes it); the later
``Begin Triggerblock <date>`` line, when present, restarts the offset base the
way python-can does. ``timestamps relative`` means each time is the delta to the
previous event, so they are summed.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from ..frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
    concat,
)
from ..runtime import speedups
from ._rows import MAX_LINE, RowSink

# the candump reader's column helpers: strided windows and grouped digit gathers
from .candump import _DIGIT, _HEX, CHUNK, PAD, _parse_hex, _parse_time, _window
from .registry import LogFormat, ReadContext, register

_DLC2LEN = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
_HEADER_RE = re.compile(rb"(?im)^\s*(base\s+(hex|dec)\b|begin\s+triggerblock\b)")
_BASE_RE = re.compile(rb"(?im)^[ \t]*base[ \t]")
_FRAME_RE = re.compile(rb"(?m)^\s*\d+\.\d+\s+(\d+\s+\S+\s+(Rx|Tx)\s+[dr]\b|CANFD\s+\d+\s+(Rx|Tx))")


class _Bad(Exception):
    """A frame line that cannot be read; the message says what was wrong."""


def sniff(head: bytes) -> bool:
    return bool(_HEADER_RE.search(head[:8192])) or len(_FRAME_RE.findall(head)) >= 2


def _date(text: str) -> float | None:
    from can.io.asc import ASCReader  # python-can costs ~70 ms to import: only for headers

    try:
        return ASCReader._datetime_to_timestamp(text.strip())
    except ValueError:
        return None


def _payload(tokens: list[str], n: int, base: int) -> bytes:
    if len(tokens) < n:
        raise _Bad(f"frame says {n} data bytes but has {len(tokens)}")
    toks = tokens[:n]
    if base == 16:
        try:
            return bytes.fromhex(" ".join(toks))
        except ValueError:
            pass  # single-digit bytes ("0") are legal in ASC: slow path below
    try:
        out = bytes(int(b, base) for b in toks)
    except ValueError:
        raise _Bad(f"invalid data byte in {' '.join(toks)!r}") from None
    return out


def _can_id(text: str, base: int) -> tuple[int, int]:
    ext = text[-1:] in ("x", "X")
    try:
        can_id = int(text[:-1] if ext else text, base)
    except ValueError:
        raise _Bad(f"invalid identifier {text!r}") from None
    if can_id > (0x1FFFFFFF if ext else 0x7FF) or can_id < 0:
        raise _Bad(f"identifier {text!r} out of range")
    return can_id, FLAG_EXT if ext else 0


class _LineParser:
    """The per-line reader: header state (date, base, relative times) and odd lines.

    `line()` reads one line into the sink (or records its problem); the bulk path
    hands it every line it does not take itself, in file order, so the header
    state it keeps is also the state the bulk rows between those lines use.
    """

    def __init__(self, ctx: ReadContext, sink: RowSink) -> None:
        self.ctx = ctx
        self.sink = sink
        self.base = 16
        self.start = 0.0
        self.date: float | None = None
        self.relative = False
        self.prev = 0.0
        self.chan_of: dict[str, int] = {}

    def line(self, n: int, raw: str) -> bool:
        """Read one line; True when the sink's batch is full."""
        ctx = self.ctx
        tok = raw.split()
        if not tok:
            return False
        first = tok[0]
        if not first[0].isdecimal():
            low = first.lower()
            if low == "date":
                self.date = _date(raw.split(None, 2)[2] if len(tok) > 2 else "")
                if self.date is None:
                    ctx.problems.add(ctx.source, f"line {n}", f"unreadable header date {raw!r}")
            elif low == "base":
                self.base = 10 if len(tok) > 1 and tok[1].lower() == "dec" else 16
                self.relative = "relative" in (x.lower() for x in tok[2:])
                if self.date is not None and not self.relative:
                    self.start = self.date
                    ctx.absolute_time = True
                    ctx.start_time = self.date
            elif low == "begin" and len(tok) > 3 and tok[1].lower() == "triggerblock":
                trig = _date(raw.split(None, 3)[3])
                if trig is not None and ctx.absolute_time:
                    self.start = trig
                    ctx.start_time = trig
            elif low.startswith("//") or low in ("end", "internal", "no", "begin"):
                pass
            else:
                ctx.problems.add(ctx.source, f"line {n}", f"not an ASC line: {raw.strip()[:60]!r}")
            return False
        try:
            t = float(first)
        except ValueError:
            ctx.problems.add(ctx.source, f"line {n}", f"invalid timestamp {first!r}")
            return False
        if self.relative:
            t += self.prev
            self.prev = t
        if len(tok) < 3:
            return False
        try:
            return self._frame(tok, t, n)
        except _Bad as e:
            ctx.problems.add(ctx.source, f"line {n}", str(e))
            return False

    def _frame(self, tok: list[str], t: float, n: int) -> bool:
        base, start, sink = self.base, self.start, self.sink
        add = sink.add
        ch = tok[1]
        chan = self.chan_of.get(ch)
        if chan is None and ch.isdecimal():
            chan = self.chan_of[ch] = sink.channel(str(int(ch)))
        if chan is None:
            if ch == "CANFD":
                return _fd_frame(tok, base, start + t, n, sink)
            return False  # "Start of measurement", "CAN 1 Status:..." and other events
        third = tok[2]
        if third[0] in "Ee" and third.lower().startswith("errorframe"):
            return add(start + t, 0, FLAG_ERR, 0, b"", chan, n)
        if len(tok) < 5:
            return False
        direction = tok[3]
        if direction == "Rx":
            flags = 0
        elif direction == "Tx":
            flags = FLAG_TX
        else:
            return False  # statistics, status, J1939TP and other events
        if third[-1] in "xX":
            flags |= FLAG_EXT
            can_id, _ = _can_id(third, base)
        else:
            try:
                can_id = int(third, base)
            except ValueError:
                raise _Bad(f"invalid identifier {third!r}") from None
            if not 0 <= can_id <= 0x7FF:
                raise _Bad(f"identifier {third!r} out of range")
        kind = tok[4]
        if kind == "d":
            if len(tok) < 6:
                raise _Bad("missing DLC")
            try:
                code = int(tok[5], base)
            except ValueError:
                raise _Bad(f"invalid DLC {tok[5]!r}") from None
            if code < 0:
                raise _Bad(f"invalid DLC {tok[5]!r}")
            size = code if code < 8 else 8  # classic CAN: DLC 9..15 still mean 8 bytes
            if base == 16 and len(tok) >= 6 + size:
                try:
                    data = bytes.fromhex(" ".join(tok[6 : 6 + size]))
                except ValueError:
                    data = _payload(tok[6:], size, base)
                else:
                    if len(data) != size:
                        data = _payload(tok[6:], size, base)
            else:
                data = _payload(tok[6:], size, base)
            return add(start + t, can_id, flags, size, data, chan, n)
        if kind in ("r", "R"):
            size = int(tok[5], base) if len(tok) > 5 and tok[5].isdecimal() else 0
            return add(start + t, can_id, flags | FLAG_RTR, min(size, 8), b"", chan, n)
        raise _Bad(f"unknown frame type {kind!r}")


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    """Chunks of the file: classic data-frame lines in bulk, the rest line by line."""
    ctx.format = "asc"
    sink = RowSink(ctx)
    sink.size = 1 << 62  # flushed per chunk here, merged with the bulk rows by line number
    parser = _LineParser(ctx, sink)
    pending: list[FrameBatch] = []
    pending_rows = 0
    for part in _chunks(stream, parser):
        pending.append(part)
        pending_rows += len(part)
        while pending_rows >= ctx.batch_size:
            merged = concat(pending) if len(pending) > 1 else pending[0]
            merged.channels = tuple(sink.channels)
            out, rest = (
                merged.take(slice(0, ctx.batch_size)),
                merged.take(slice(ctx.batch_size, None)),
            )
            pending, pending_rows = ([rest] if len(rest) else []), len(rest)
            yield out
    if pending:
        out = concat(pending) if len(pending) > 1 else pending[0]
        out.channels = tuple(sink.channels)
        yield out


def _chunks(stream: BinaryIO, parser: _LineParser) -> Iterator[FrameBatch]:
    sink = parser.sink
    line_base = 0
    carry = b""
    eof = False
    skipping = False  # inside an over-long line: drop bytes up to its end
    while not eof:
        block = stream.read(CHUNK)
        eof = not block
        if skipping:
            nl_at = block.find(b"\n")
            if nl_at < 0 and not eof:
                continue
            block, skipping = block[nl_at + 1 :] if nl_at >= 0 else b"", False
        chunk = carry + block
        if not eof:
            cut = chunk.rfind(b"\n") + 1
            if cut == 0:
                carry = chunk
                if len(carry) > MAX_LINE:  # never hold a newline-less file whole
                    line_base += 1
                    parser.ctx.problems.add(
                        parser.ctx.source,
                        f"line {line_base}",
                        f"line longer than {MAX_LINE} bytes, skipped",
                    )
                    carry, skipping = b"", True
                continue
            chunk, carry = chunk[:cut], chunk[cut:]
        elif not chunk:
            break
        C = speedups.C
        if C is not None:
            starts = np.empty(C.count_lines(chunk), np.int64)
            ends = np.empty(starts.size, np.int64)
            C.split_lines(chunk, starts, ends, True)  # text_lines strips every trailing CR
        else:
            arr = np.frombuffer(chunk + bytes(PAD), np.uint8)
            nl = np.flatnonzero(arr[: len(chunk)] == 10)
            if nl.size == 0 or nl[-1] != len(chunk) - 1:
                nl = np.append(nl, len(chunk))
            starts = np.empty(nl.size, np.int64)
            starts[0] = 0
            starts[1:] = nl[:-1] + 1
            ends = nl.astype(np.int64)
            while True:  # text_lines strips every trailing CR
                cr = (ends > starts) & (arr[np.maximum(ends - 1, 0)] == 13)
                if not cr.any():
                    break
                ends = ends - cr
        first_line = line_base + 1
        line_base += starts.size
        # header lines that set the base or the time mode come first, line by line
        head_end = 0
        if C is not None:  # the regex's lines, found per line start in C; then the same test
            head_end = C.asc_base_line(chunk, starts)
            if head_end and not (b"ase" in chunk or b"ASE" in chunk):
                head_end = 0
        elif b"ase" in chunk or b"ASE" in chunk:  # memchr-fast test before the regex
            for m in _BASE_RE.finditer(chunk):
                head_end = int(np.searchsorted(starts, m.start(), side="right"))
        for i in range(head_end):
            parser.line(first_line + i, chunk[starts[i] : ends[i]].decode("latin-1"))
        bulk = None
        if parser.base == 16 and not parser.relative and head_end < starts.size:
            bulk = _c_bulk_lines(C, chunk, starts, ends) if C else _bulk_lines(arr, starts, ends)
            if bulk[1] is None:
                bulk = None
            else:
                bulk[0][:head_end] = False
        fast = np.zeros(starts.size, bool) if bulk is None else bulk[0]
        # every other line, in order, through the line parser; note where the time base moves
        slow_idx = np.flatnonzero(~fast[head_end:]) + head_end
        state_at: list[tuple[int, float]] = [(-1, parser.start)]
        new_chans = _first_channels(bulk, parser) if bulk is not None else []
        nc = 0
        for i in slow_idx.tolist():
            while nc < len(new_chans) and new_chans[nc][0] < i:
                parser.chan_of.setdefault(new_chans[nc][1], sink.channel(new_chans[nc][1]))
                nc += 1
            parser.line(first_line + i, chunk[starts[i] : ends[i]].decode("latin-1"))
            if parser.start != state_at[-1][1]:
                state_at.append((i, parser.start))
        for _, name in new_chans[nc:]:
            parser.chan_of.setdefault(name, sink.channel(name))
        parts = []
        slow_batch = sink.flush()
        if slow_batch is not None:
            parts.append(slow_batch)
        if bulk is not None and fast.any():
            parts.append(_bulk_batch(bulk, state_at, parser, first_line, chunk, starts, ends))
        if not parts:
            continue
        if len(parts) == 2:
            merged = concat(parts)
            merged = merged.take(np.argsort(merged.line, kind="stable"))
        else:
            merged = parts[0]
        merged.channels = tuple(sink.channels)
        yield merged


def _first_channels(bulk, parser: _LineParser) -> list[tuple[int, str]]:
    """(line index, name) of the first bulk row on each channel the parser has not seen."""
    fast, chan_num = bulk[0], bulk[1]["chan"]
    rows = np.flatnonzero(fast)
    nums, first = np.unique(chan_num[rows], return_index=True)
    out = []
    for num, at in zip(nums.tolist(), first.tolist(), strict=True):
        name = str(num)
        if name not in parser.chan_of:
            out.append((int(rows[at]), name))
    return sorted(out)


def _bulk_batch(
    bulk, state_at, parser: _LineParser, first_line: int, chunk, starts, ends
) -> FrameBatch:
    """The bulk rows as a batch, each timed from the time base in force at its line."""
    fast, cols = bulk
    rows = np.flatnonzero(fast)
    take = slice(None) if rows.size == fast.size else rows  # usually every line: no copies
    if len(state_at) == 1:  # one time base for the chunk (the usual case)
        offset = np.float64(state_at[0][1])
    else:
        where = np.array([s[0] for s in state_at], np.int64)
        k = np.searchsorted(where, rows, side="left") - 1  # last Begin Triggerblock before the row
        offset = np.array([s[1] for s in state_at], np.float64)[k]
    chan = cols["chan"][take]
    names = {int(num): parser.chan_of[str(num)] for num in np.unique(chan).tolist()}
    lut = np.zeros(max(names) + 1, np.uint16)
    for num, idx in names.items():
        lut[num] = idx
    b = FrameBatch(
        t=offset + cols["t"][take],
        can_id=cols["can_id"][take],
        flags=cols["flags"][take],
        dlc=cols["dlc"][take],
        data=cols["data"][take],
        channel=lut[chan],
        line=first_line + rows.astype(np.int64),
    )
    parser.ctx.frames += len(b)
    return b


def _c_bulk_lines(C, chunk: bytes, starts: np.ndarray, ends: np.ndarray):
    """`_bulk_lines` by the compiled helper: the same lines taken, the same columns."""
    n = starts.size
    ok = np.zeros(n, bool)
    cols = {
        "t": np.empty(n, np.float64),
        "chan": np.empty(n, np.int64),
        "can_id": np.empty(n, np.uint32),
        "flags": np.empty(n, np.uint8),
        "dlc": np.empty(n, np.uint8),
        "data": np.empty((n, 8), np.uint8),
    }
    C.asc_lines(chunk, starts, ends, *cols.values(), ok)
    return ok, cols


def _bulk_lines(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray):
    """Classic data-frame lines of a chunk as columns (base hex, absolute times).

    `t ch id[x] Rx|Tx d dlc b0 b1 ...`: whitespace tokens are found once for the
    whole chunk, then each field is a fixed-position gather per line. Returns
    (mask of lines taken, columns); every other line goes to the line parser.
    """
    n = starts.size
    size = arr.size - PAD
    body = arr[:size]
    tokch = np.ones(size + 2, bool)  # token bytes, with a separator either side
    tokch[0] = tokch[-1] = False
    inner = tokch[1:-1]
    inner &= body > 32  # space, tab, CR, LF and other controls separate tokens
    tok_s = np.flatnonzero(inner & ~tokch[:-2])
    tok_len = np.flatnonzero(inner & ~tokch[2:]) + 1 - tok_s
    first = np.searchsorted(tok_s, starts)
    ntok = np.searchsorted(tok_s, ends) - first
    ok = ntok >= 6
    # str.split() also splits on other controls and on latin-1 NBSP/NEL: such lines go slow
    odd = np.flatnonzero(((body < 32) & (body != 9) & (body != 10) & (body != 13)) | (body >= 127))
    if odd.size:
        k = np.searchsorted(odd, starts)
        ok &= ~((k < odd.size) & (odd[np.minimum(k, odd.size - 1)] < ends))
    nt = tok_s.size
    if nt == 0:
        return np.zeros(n, bool), None

    def tok(k: int):
        j = np.minimum(first + k, nt - 1)
        return tok_s[j], tok_len[j]

    t_s, t_len = tok(0)
    c_s, c_len = tok(1)
    i_s, i_len = tok(2)
    d_s, d_len = tok(3)
    k_s, k_len = tok(4)
    l_s, l_len = tok(5)
    # time: digits '.' digits, no exponent
    dots = np.flatnonzero(body == ord("."))
    t, t_ok = _parse_time(arr, t_s, t_s + t_len, dots)
    ok &= t_ok & (t_len >= 3)
    # channel: 1-3 decimal digits
    cw = _DIGIT[_window(arr, c_s, 3)].astype(np.int64)
    c_digit = cw != 255
    ok &= (c_len >= 1) & (c_len <= 3) & np.all(c_digit | (np.arange(3) >= c_len[:, None]), axis=1)
    chan = np.zeros(n, np.int64)
    for w in (1, 2, 3):
        r = c_len == w
        chan[r] = cw[r, :w] @ (10 ** np.arange(w - 1, -1, -1))
    # direction
    dw = _window(arr, d_s, 2)
    rx = (dw[:, 0] == ord("R")) & (dw[:, 1] == ord("x"))
    tx = (dw[:, 0] == ord("T")) & (dw[:, 1] == ord("x"))
    ok &= (d_len == 2) & (rx | tx)
    ok &= (k_len == 1) & (arr[k_s] == ord("d"))
    code = _HEX[arr[l_s]].astype(np.int64)
    ok &= (l_len == 1) & (code != 255)
    dlc = np.minimum(np.where(code == 255, 0, code), 8)
    ok &= ntok >= 6 + dlc
    # identifier: hex digits, then 'x' for 29-bit
    last = arr[i_s + np.maximum(i_len - 1, 0)]
    ext = (last == ord("x")) | (last == ord("X"))
    id_len = i_len - ext
    can_id, id_ok = _parse_hex(arr, i_s, np.where(ok, id_len, 0), 8)
    ok &= id_ok & (id_len >= 1) & (id_len <= 8)
    ok &= np.where(ext, can_id <= 0x1FFFFFFF, can_id <= 0x7FF)
    # data bytes: tokens 6.. of exactly two hex digits
    data = np.zeros((n, 8), np.uint8)
    for j in range(8):
        has = ok & (dlc > j)
        if not has.any():
            continue
        s, ln = tok(6 + j)
        hi, lo = _HEX[arr[s]], _HEX[arr[s + 1]]
        good = (ln == 2) & (hi != 255) & (lo != 255)
        ok &= ~has | good
        data[:, j] = np.where(has, (hi << 4) | (lo & 0x0F), 0)
    flags = np.where(tx, FLAG_TX, 0).astype(np.uint8) | np.where(ext, FLAG_EXT, 0).astype(np.uint8)
    cols = {
        "t": t,
        "chan": chan,
        "can_id": can_id.astype(np.uint32),
        "flags": flags,
        "dlc": dlc.astype(np.uint8),
        "data": data,
    }
    return ok, cols


def _fd_frame(tok: list[str], base: int, t: float, n: int, sink: RowSink) -> bool:
    # t CANFD ch dir id [name] brs esi dlc length data... (see python-can ASCWriter)
    if len(tok) < 5 or not tok[2].isdecimal() or tok[3] not in ("Rx", "Tx"):
        raise _Bad("malformed CANFD line")
    chan = sink.channel(str(int(tok[2])))
    flags = FLAG_FD | (FLAG_TX if tok[3] == "Tx" else 0)
    if tok[4].lower().startswith("errorframe"):
        return sink.add(t, 0, flags | FLAG_ERR, 0, b"", chan, n)
    can_id, ext = _can_id(tok[4], base)
    i = 5 if len(tok) > 5 and tok[5].isdecimal() else 6
    if len(tok) < i + 4:
        raise _Bad("CANFD line too short")
    brs, esi = tok[i], tok[i + 1]
    try:
        code = int(tok[i + 2], base)
        length = int(tok[i + 3])
    except ValueError:
        raise _Bad(f"invalid DLC/length {tok[i + 2]!r} {tok[i + 3]!r}") from None
    if not 0 <= code <= 15 or not 0 <= length <= 64:
        raise _Bad(f"invalid DLC/length {tok[i + 2]!r} {tok[i + 3]!r}")
    flags |= ext | (FLAG_BRS if brs == "1" else 0) | (FLAG_ESI if esi == "1" else 0)
    if length == 0:
        return sink.add(t, can_id, flags | FLAG_RTR, _DLC2LEN[code], b"", chan, n)
    data = _payload(tok[i + 4 :], length, base)
    return sink.add(t, can_id, flags, length, data, chan, n)


FORMAT = register(
    LogFormat(
        name="asc",
        description="Vector ASC text log",
        sniff=sniff,
        read=read,
        suffixes=(".asc",),
        priority=30,
    )
)


def read_per_line(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    """Every line through the line parser: the bulk reader's reference in the tests."""
    ctx.format = "asc"
    sink = RowSink(ctx)
    parser = _LineParser(ctx, sink)
    for n, raw in enumerate(stream, 1):
        if parser.line(n, raw.decode("latin-1").rstrip("\r\n")):
            yield sink.flush()
    yield from sink.drain()
