"""RowSink: fills one FrameBatch at a time for text readers that parse line by line.

Text formats (ASC, TRC, IXXAT, CSV) have to be tokenised per line, but the rows
must not live as Python objects: the sink appends to compact ``array.array``
columns and a ``bytearray`` of 8-byte data slots, and hands out a FrameBatch of
``ctx.batch_size`` rows at a time, so memory does not grow with the log.
"""

from __future__ import annotations

import codecs
import re
from array import array
from collections.abc import Iterator

import numpy as np

from cananalyze.core.frames import FrameBatch, channel_index
from cananalyze.formats.registry import ReadContext

_ZERO8 = bytes(8)
EPOCH_2000 = 946684800.0  # a first time stamp later than this is taken as Unix time


def _finite(t: float) -> bool:
    return -1e300 < t < 1e300  # False for NaN and infinities; cheaper than math.isfinite


def _why(t: float, can_id: int, dlc: int, payload: bytes) -> str:
    if not 0 <= can_id <= 0x1FFFFFFF:
        return f"identifier {can_id:#x} out of range"
    if not 0 <= dlc <= 64 or len(payload) > 64:
        return f"{max(dlc, len(payload))} data bytes is more than a CAN frame carries"
    return f"timestamp {t!r} is not a usable time"


class RowSink:
    """Append rows, flush full batches; keeps the channel table stable across batches."""

    def __init__(self, ctx: ReadContext, epoch_times: bool = False) -> None:
        """epoch_times: the format has no header saying whether its times are absolute,
        so a first time stamp after the year 2000 is taken as Unix time (CSV, python-can)."""
        self.ctx = ctx
        self.epoch_times = epoch_times
        self.size = max(1, int(ctx.batch_size))
        self.channels: list[str] = []
        self._chan_index: dict[str, int] = {}
        self._reset()

    def _reset(self) -> None:
        self.t = array("d")
        self.can_id = array("I")
        self.flags = array("B")
        self.dlc = array("B")
        self.chan = array("H")
        self.line = array("q")
        self.data = bytearray()
        self.long: dict[int, bytes] = {}

    def channel(self, name: str) -> int:
        """Index of a channel name, adding it to the table on first sight."""
        return channel_index(self.channels, self._chan_index, name)

    def add(
        self, t: float, can_id: int, flags: int, dlc: int, payload: bytes, chan: int, line: int
    ) -> bool:
        """Append one row; ``payload`` is the data bytes (may exceed 8 for CAN FD).

        Returns True when the batch is full and should be flushed. A value no
        CAN frame can have (negative or over-wide identifier, DLC over 64, a
        time that is not a finite number) is reported as a problem of that line
        and the row is dropped, so no reader's parsing slip can corrupt a column.
        """
        n = len(self.line)
        if not (0 <= can_id <= 0x1FFFFFFF and 0 <= dlc <= 64 and len(payload) <= 64 and _finite(t)):
            self.ctx.problems.add(self.ctx.source, f"line {line}", _why(t, can_id, dlc, payload))
            return False
        self.t.append(t)
        self.can_id.append(can_id)
        self.flags.append(flags)
        self.dlc.append(dlc)
        self.chan.append(chan)
        self.line.append(line)
        k = len(payload)
        if k >= 8:
            self.data += payload[:8]
            if k > 8:
                self.long[n] = bytes(payload)
        else:
            self.data += payload
            self.data += _ZERO8[k:]
        return n + 1 >= self.size

    def __len__(self) -> int:
        return len(self.line)

    def flush(self) -> FrameBatch | None:
        """The rows gathered so far as a FrameBatch (None if empty); starts a new batch."""
        n = len(self.line)
        if n == 0:
            return None
        if self.epoch_times and self.ctx.frames == 0 and self.t[0] > EPOCH_2000:
            self.ctx.absolute_time = True
            self.ctx.start_time = self.t[0]
        batch = FrameBatch(
            t=np.frombuffer(self.t, np.float64).copy(),
            can_id=np.frombuffer(self.can_id, np.uint32).copy(),
            flags=np.frombuffer(self.flags, np.uint8).copy(),
            dlc=np.frombuffer(self.dlc, np.uint8).copy(),
            data=np.frombuffer(bytes(self.data), np.uint8).reshape(n, 8),
            channel=np.frombuffer(self.chan, np.uint16).copy(),
            line=np.frombuffer(self.line, np.int64).copy(),
            channels=tuple(self.channels),
            long_data=self.long,
        )
        self.ctx.frames += n
        self._reset()
        return batch

    def drain(self) -> Iterator[FrameBatch]:
        """Yield the final partial batch, if any."""
        batch = self.flush()
        if batch is not None:
            yield batch


MAX_LINE = 1 << 16  # bytes; real log lines are under 400 (CAN FD ASC), this bounds memory
BLOCK = 1 << 20  # bytes read at a time by text_lines
# A line of nothing but these is blank to every text reader (all that str.strip() takes
# from its latin-1 text is whitespace): runs of such lines are skipped in bulk.
_BLANK = " \t\r\x0b\x0c"
_INK = re.compile(r"[^ \t\r\x0b\x0c\n]")  # a character that makes a line more than blank
_SPACES = str.maketrans("\t\r\x0b\x0c", "    ")


def text_lines(
    stream, encoding: str = "latin-1", ctx: ReadContext | None = None, skip_blank: bool = False
) -> Iterator[tuple[int, str]]:
    """(1-based line number, line without end-of-line) of a binary (or text) stream, streamed.

    Latin-1 never fails to decode, so a stray byte becomes a parse problem on
    its own line rather than a UnicodeDecodeError for the whole file. A line
    longer than MAX_LINE (binary junk, a file with no newlines) is never held
    whole: with ``ctx`` it is reported and skipped, else its start is yielded
    and the parser will find it malformed.

    The stream is read BLOCK bytes at a time and cut at its newlines. ``skip_blank``:
    lines of nothing but spaces, tabs, CR, VT and FF (those every text reader skips)
    are not yielded, and a run of them costs one regular-expression search and one
    count, not a Python step per line: 10 MiB of blank lines read at candump's speed
    (issue 38). A too-long one is still reported, as without ``skip_blank``.
    """
    read = stream.read
    first = read(BLOCK)
    if isinstance(first, str):  # a TextIOWrapper (universal newlines) works too
        decode = None
        buf = first
    else:
        decode = codecs.getincrementaldecoder(encoding)().decode
        buf = decode(first)
    ended = not first
    n = 0  # the lines consumed so far: the number of the last one
    pos = 0  # where the next line starts in buf

    def more() -> str:
        nonlocal ended
        if ended:
            return ""
        block = read(BLOCK)
        ended = not block
        return block if decode is None else decode(block, final=ended)

    after_blank = False  # the last line was blank: more may follow
    while True:
        if skip_blank and pos < len(buf) and (after_blank or buf[pos] in "\n\r"):
            # blank lines from here: skip the whole ones up to the next ink, in bulk
            after_blank = False
            ink = _INK.search(buf, pos)
            stop = buf.rfind("\n", pos, len(buf) if ink is None else ink.start()) + 1
            if stop - pos >= MAX_LINE:  # a blank line too long for a log line: stop there
                long = buf[pos:stop].translate(_SPACES).find(" " * MAX_LINE)
                if long >= 0:
                    stop = buf.rfind("\n", pos, pos + long) + 1
            if stop > pos:
                n += buf.count("\n", pos, stop)
                pos = stop
                continue
        end = buf.find("\n", pos)
        if end < 0 and len(buf) - pos < MAX_LINE:
            block = more()
            if block:
                buf = buf[pos:] + block
                pos = 0
                continue
            if pos >= len(buf):
                return
            n += 1  # the last line, without a newline
            line, pos = buf[pos:], len(buf)
            if not (skip_blank and not line.strip(_BLANK)):
                yield n, line.rstrip("\r\n")
            continue
        n += 1
        if 0 <= end < pos + MAX_LINE:
            line, pos = buf[pos:end], end + 1
            if skip_blank and line[:1] in _BLANK and not line.strip(_BLANK):
                after_blank = True  # spaces only (a line of content may start with some)
                continue
            yield n, line.rstrip("\r")
            continue
        # a line of MAX_LINE or more: its start kept, the rest dropped a block at a time
        start = buf[pos : pos + MAX_LINE]
        if end >= 0:
            size, pos = end + 1 - pos, end + 1
        else:
            size = len(buf) - pos
            while True:
                buf, pos = more(), 0
                end = buf.find("\n")
                if not buf or end >= 0:
                    size += end + 1 if buf else 0
                    pos = end + 1 if buf else 0
                    break
                size += len(buf)
        if ctx is not None:
            ctx.problems.add(
                ctx.source,
                f"line {n}",
                f"line of {size} bytes is too long for a log line, skipped",
            )
            continue
        if not (skip_blank and not start.strip(_BLANK)):
            yield n, start.rstrip("\r\n")


def inked_lines(text: str) -> Iterator[tuple[int, str]]:
    """(0-based index, line without its newline) of the lines of `text` that are not
    blank (text_lines' `skip_blank`); a run of blank lines costs one search and one
    count, not a Python step per line."""
    pos, i, size = 0, 0, len(text)
    after_blank = False
    while pos < size:
        if after_blank or text[pos] in "\n\r":  # blank lines, maybe many: to the next ink
            after_blank = False
            ink = _INK.search(text, pos)
            if ink is None:
                return
            nl = text.rfind("\n", pos, ink.start())  # the ink's line starts after it
            if nl >= 0:
                i += text.count("\n", pos, nl + 1)
                pos = nl + 1
        end = text.find("\n", pos)
        if end < 0:
            end = size
        line = text[pos:end]
        if line[:1] in _BLANK and not line.strip(_BLANK):
            after_blank = True
        else:
            yield i, line
        i += 1
        pos = end + 1
