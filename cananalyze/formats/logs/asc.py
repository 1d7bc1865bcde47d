"""Vector ASC text logs: classic and CAN FD frames, remote and error frames.

python-can's ASCReader builds one Message per frame and silently drops lines it
cannot parse; this reader tokenises each line straight into a RowSink (columns),
and reports malformed frame lines with their line number. With the compiled
helper, classic data-frame lines (the bulk of a log) are parsed in C, in bulk,
with the same values; the line parser takes the rest. It follows python-can
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
    concat,
)
from cananalyze.formats.logs._pycan_writer import PycanWriter
from cananalyze.formats.logs._rows import MAX_LINE, RowSink, inked_lines
from cananalyze.formats.logs.candump import CHUNK
from cananalyze.formats.registry import LogFormat, ReadContext, register
from cananalyze.runtime import speedups

_DLC2LEN = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
# `[ \t]*`, not `\s*`: under (?m) `^\s*` runs over newlines from every line start,
# quadratic on a run of blank lines (64k blank lines took 16-50 s to sniff)
_HEADER_RE = re.compile(rb"(?im)^[ \t]*(base\s+(hex|dec)\b|begin\s+triggerblock\b)")
_FRAME_RE = re.compile(
    rb"(?m)^[ \t]*\d+\.\d+\s+(\d+\s+\S+\s+(Rx|Tx)\s+[dr]\b|CANFD\s+\d+\s+(Rx|Tx))"
)


class _Bad(Exception):
    """A frame line that cannot be read; the message says what was wrong."""


def sniff(head: bytes) -> bool:
    return bool(_HEADER_RE.search(head[:8192])) or len(_FRAME_RE.findall(head)) >= 2


# The header date as python-can's ASCReader._datetime_to_timestamp reads it (English and
# German month names, 12- or 24-hour clock, with or without milliseconds, local time),
# restated: importing python-can for it cost every ASC read 70-80 ms, and 0.5 s in a
# library process, where python-can also imports asammdf. tests/formats/test_asc_date.py
# holds it to python-can's own answer.
_MONTHS = {
    **{m: k for k, m in enumerate("Jan Feb Mar Apr May Jun Jul Aug Sep Oct Nov Dec".split(), 1)},
    "Mär": 3,
    "Mai": 5,
    "Okt": 10,
    "Dez": 12,
}
_DATE_FORMATS = (
    "%m %d %I:%M:%S.%f %p %Y",
    "%m %d %I:%M:%S %p %Y",
    "%m %d %H:%M:%S.%f %Y",
    "%m %d %H:%M:%S %Y",
)


def _date(text: str) -> float | None:
    """Seconds since the epoch of a `date` line's text after the weekday, or None."""
    text = text.strip()
    for name, number in _MONTHS.items():
        text = text.replace(name, f"{number:02d}")
    for form in _DATE_FORMATS:
        try:
            return datetime.strptime(text, form).timestamp()
        except ValueError:
            continue
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
    """Chunks of the file: classic data-frame lines in bulk (C helper), the rest line by line."""
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
    carry = b""  # the partial line after a chunk's last newline
    eof = False
    skipping = False  # inside an over-long line: drop bytes up to its end
    # the file is read into one reused buffer after the carried line: the chunk is a view
    # of it, and neither the block nor the chunk is copied (streams without readinto: bytes)
    readinto = getattr(stream, "readinto", None)
    buf = bytearray()
    while not eof:
        start = len(carry)
        if readinto is not None:
            if len(buf) < start + CHUNK:
                buf = bytearray(start + CHUNK)
            buf[:start] = carry
            got = readinto(memoryview(buf)[start : start + CHUNK]) or 0
            data = buf
        else:
            block = stream.read(CHUNK)
            got, data = len(block), carry + block
        eof = not got
        size = start + got
        lo = 0
        if skipping:  # nothing is carried then
            nl_at = data.find(b"\n", 0, size)
            if nl_at < 0 and not eof:
                continue
            lo, skipping = nl_at + 1 if nl_at >= 0 else size, False
        if not eof:
            cut = data.rfind(b"\n", lo, size) + 1
            if cut == 0:
                carry = bytes(data[lo:size])
                if len(carry) > MAX_LINE:  # never hold a newline-less file whole
                    line_base += 1
                    parser.ctx.problems.add(
                        parser.ctx.source,
                        f"line {line_base}",
                        f"line longer than {MAX_LINE} bytes, skipped",
                    )
                    carry, skipping = b"", True
                continue
            chunk, carry = memoryview(data)[lo:cut], bytes(data[cut:size])
        elif lo == size:
            break
        else:
            chunk, carry = memoryview(data)[lo:size], b""
        first_line = line_base + 1
        C = speedups.C
        if C is None:  # every line through the line parser, in order, but the blank ones
            text = bytes(chunk).decode("latin-1")  # (nothing to it), skipped in bulk
            line_base += text.count("\n") + (not text.endswith("\n"))
            for i, raw in inked_lines(text):
                parser.line(first_line + i, raw.rstrip("\r"))
            merged = sink.flush()
        else:
            n_lines, merged = _c_fast_chunk(C, parser, chunk, first_line)
            if n_lines < 0:  # a header line in the chunk, or a base/time mode the C parser leaves
                starts = np.empty(C.count_lines(chunk), np.int64)
                ends = np.empty(starts.size, np.int64)
                C.split_lines(chunk, starts, ends, True)  # text_lines strips every trailing CR
                n_lines = starts.size
                merged = _c_chunk(C, parser, chunk, starts, ends, first_line)
            line_base += n_lines
        if merged is not None:
            merged.channels = tuple(sink.channels)
            yield merged


def _c_fast_chunk(C, parser: _LineParser, chunk, first_line: int) -> tuple[int, FrameBatch | None]:
    """The usual chunk (hex base, absolute times, no `base` header line) in one C pass:
    (lines in it, its frames or None). (-1, None) leaves the chunk to `_c_chunk`.

    The C pass cuts the lines, parses the classic data-frame lines straight into
    compact columns and lists the others, which go through the line parser in file
    order, as in `_c_chunk` (whose results these are, without its per-line arrays).
    """
    if parser.base != 16 or parser.relative:
        return -1, None
    sink = parser.sink
    # room for every frame line (14 bytes at least, and its newline) and for a few other
    # lines; a chunk with more of those (hostile, or all events) is counted and run again
    rows, others = len(chunk) // 15 + 1, len(chunk) // 256 + 64
    for _ in range(2):
        t = np.empty(rows, np.float64)
        chan = np.empty(rows, np.uint16)
        can_id = np.empty(rows, np.uint32)
        flags = np.empty(rows, np.uint8)
        dlc = np.empty(rows, np.uint8)
        data = np.empty((rows, 8), np.uint8)
        line = np.empty(rows, np.int64)
        slow = np.empty((others, 3), np.int64)
        first_row = np.full(1000, -1, np.int64)  # channel numbers have 1-3 digits
        n_lines, n, n_slow, last_base = C.asc_chunk(
            chunk, first_line, t, chan, can_id, flags, dlc, data, line, slow, first_row
        )
        if n_lines >= 0:
            break
        rows = others = C.count_lines(chunk)
    if last_base:
        return -1, None
    nums = np.flatnonzero(first_row >= 0).tolist()
    new_chans = sorted(
        (int(line[first_row[num]]), str(num)) for num in nums if str(num) not in parser.chan_of
    )
    # every other line, in order, through the line parser; note where the time base moves
    state_at: list[tuple[int, float]] = [(-1, parser.start)]
    nc = 0
    for i, s, e in slow[:n_slow].tolist():
        at = first_line + i
        while nc < len(new_chans) and new_chans[nc][0] < at:
            parser.chan_of.setdefault(new_chans[nc][1], sink.channel(new_chans[nc][1]))
            nc += 1
        parser.line(at, bytes(chunk[s:e]).decode("latin-1"))
        if parser.start != state_at[-1][1]:
            state_at.append((at, parser.start))
    for _, name in new_chans[nc:]:
        parser.chan_of.setdefault(name, sink.channel(name))
    parts = []
    slow_batch = sink.flush()
    if slow_batch is not None:
        parts.append(slow_batch)
    if n:
        t, line = t[:n], line[:n]
        if len(state_at) == 1:  # one time base for the chunk (the usual case)
            t += np.float64(state_at[0][1])
        else:
            where = np.array([s[0] for s in state_at], np.int64)
            k = np.searchsorted(where, line, side="left") - 1  # last Begin Triggerblock before
            t += np.array([s[1] for s in state_at], np.float64)[k]
        if len(nums) == 1:
            channel = np.full(n, parser.chan_of[str(nums[0])], np.uint16)
        else:
            lut = np.zeros(max(nums) + 1, np.uint16)
            for num in nums:
                lut[num] = parser.chan_of[str(num)]
            channel = lut[chan[:n]]
        parts.append(
            FrameBatch(
                t=t,
                can_id=can_id[:n],
                flags=flags[:n],
                dlc=dlc[:n],
                data=data[:n],
                channel=channel,
                line=line,
            )
        )
        parser.ctx.frames += n
    if not parts:
        return n_lines, None
    if len(parts) == 1:
        return n_lines, parts[0]
    merged = concat(parts)
    return n_lines, merged.take(np.argsort(merged.line, kind="stable"))


def _c_chunk(C, parser: _LineParser, chunk, starts, ends, first_line: int):
    """One chunk's frames: data-frame lines by the compiled parser, the rest by the line
    parser in file order; None when the chunk has none."""
    sink = parser.sink
    # header lines that set the base or the time mode come first, line by line:
    # the last `base ...` line is found per line start in C
    head_end = C.asc_base_line(chunk, starts)
    for i in range(head_end):
        parser.line(first_line + i, bytes(chunk[starts[i] : ends[i]]).decode("latin-1"))
    bulk = None
    if parser.base == 16 and not parser.relative and head_end < starts.size:
        bulk = _c_bulk_lines(C, chunk, starts, ends)
        bulk[0][:head_end] = False
    fast = np.zeros(starts.size, bool) if bulk is None else bulk[0]
    # every other line, in order, through the line parser; note where the time base moves
    slow_idx = np.flatnonzero(~fast[head_end:]) + head_end
    slow_idx = slow_idx[ends[slow_idx] > starts[slow_idx]]  # empty lines mean nothing to it
    state_at: list[tuple[int, float]] = [(-1, parser.start)]
    new_chans = _first_channels(bulk, parser) if bulk is not None else []
    nc = 0
    for i in slow_idx.tolist():
        while nc < len(new_chans) and new_chans[nc][0] < i:
            parser.chan_of.setdefault(new_chans[nc][1], sink.channel(new_chans[nc][1]))
            nc += 1
        parser.line(first_line + i, bytes(chunk[starts[i] : ends[i]]).decode("latin-1"))
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
        return None
    if len(parts) == 1:
        return parts[0]
    merged = concat(parts)
    return merged.take(np.argsort(merged.line, kind="stable"))


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
    """Classic data-frame lines (base hex, absolute times) by the compiled helper:
    (mask of lines taken, columns); every other line is the line parser's."""
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


class AscWriter(PycanWriter):
    """python-can's ASCWriter, the reference for the format; the header's date is the
    first frame's, not the wall clock's, so written files are reproducible."""

    def __init__(self, path: Path) -> None:
        import can

        super().__init__(path, can.ASCWriter)

    def close(self) -> None:
        open_ = self._writer is not None
        super().close()
        if open_ and self.start is not None:
            _set_asc_date(self.path, self.start)


def _set_asc_date(path: Path, start: float) -> None:
    """python-can stamps the ASC `date` line with the wall clock; use the log's start."""
    import can

    lines = path.read_text(encoding="ascii").split("\n")
    if lines and lines[0].startswith("date "):
        stamp = can.ASCWriter._format_header_datetime(can.ASCWriter, datetime.fromtimestamp(start))  # type: ignore[arg-type]
        lines[0] = f"date {stamp}"
        path.write_text("\n".join(lines), encoding="ascii")


FORMAT = register(
    LogFormat(
        name="asc",
        description="Vector ASC text log",
        sniff=sniff,
        read=read,
        suffixes=(".asc",),
        priority=31,
        write_suffix=".asc",
        writer=AscWriter,
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
