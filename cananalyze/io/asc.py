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

from can.io.asc import ASCReader

from ..frames import FLAG_BRS, FLAG_ERR, FLAG_ESI, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX, FrameBatch
from ._rows import RowSink, text_lines
from .registry import LogFormat, ReadContext, register

_DLC2LEN = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
_HEADER_RE = re.compile(rb"(?im)^\s*(base\s+(hex|dec)\b|begin\s+triggerblock\b)")
_FRAME_RE = re.compile(rb"(?m)^\s*\d+\.\d+\s+(\d+\s+\S+\s+(Rx|Tx)\s+[dr]\b|CANFD\s+\d+\s+(Rx|Tx))")


class _Bad(Exception):
    """A frame line that cannot be read; the message says what was wrong."""


def sniff(head: bytes) -> bool:
    return bool(_HEADER_RE.search(head[:8192])) or len(_FRAME_RE.findall(head)) >= 2


def _date(text: str) -> float | None:
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


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "asc"
    sink = RowSink(ctx)
    base = 16
    start = 0.0
    date: float | None = None
    relative = False
    prev = 0.0
    add = sink.add
    channel = sink.channel
    chan_of: dict[str, int] = {}
    fromhex = bytes.fromhex
    for n, raw in text_lines(stream, ctx=ctx):
        tok = raw.split()
        if not tok:
            continue
        first = tok[0]
        if not first[0].isdecimal():
            low = first.lower()
            if low == "date":
                date = _date(raw.split(None, 2)[2] if len(tok) > 2 else "")
                if date is None:
                    ctx.problems.add(ctx.source, f"line {n}", f"unreadable header date {raw!r}")
            elif low == "base":
                base = 10 if len(tok) > 1 and tok[1].lower() == "dec" else 16
                relative = "relative" in (x.lower() for x in tok[2:])
                if date is not None and not relative:
                    start = date
                    ctx.absolute_time = True
                    ctx.start_time = date
            elif low == "begin" and len(tok) > 3 and tok[1].lower() == "triggerblock":
                trig = _date(raw.split(None, 3)[3])
                if trig is not None and ctx.absolute_time:
                    start = trig
                    ctx.start_time = trig
            elif low.startswith("//") or low in ("end", "internal", "no", "begin"):
                pass
            else:
                ctx.problems.add(ctx.source, f"line {n}", f"not an ASC line: {raw.strip()[:60]!r}")
            continue
        try:
            t = float(first)
        except ValueError:
            ctx.problems.add(ctx.source, f"line {n}", f"invalid timestamp {first!r}")
            continue
        if relative:
            t += prev
            prev = t
        if len(tok) < 3:
            continue
        ch = tok[1]
        try:
            chan = chan_of.get(ch)
            if chan is None and ch.isdecimal():
                chan = chan_of[ch] = channel(str(int(ch)))
            if chan is not None:
                third = tok[2]
                if third[0] in "Ee" and third.lower().startswith("errorframe"):
                    add(start + t, 0, FLAG_ERR, 0, b"", chan, n)
                    continue
                if len(tok) < 5:
                    continue
                direction = tok[3]
                if direction == "Rx":
                    flags = 0
                elif direction == "Tx":
                    flags = FLAG_TX
                else:
                    continue  # statistics, status, J1939TP and other events
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
                            data = fromhex(" ".join(tok[6 : 6 + size]))
                        except ValueError:
                            data = _payload(tok[6:], size, base)
                        else:
                            if len(data) != size:
                                data = _payload(tok[6:], size, base)
                    else:
                        data = _payload(tok[6:], size, base)
                    full = add(start + t, can_id, flags, size, data, chan, n)
                elif kind in ("r", "R"):
                    size = int(tok[5], base) if len(tok) > 5 and tok[5].isdecimal() else 0
                    full = add(start + t, can_id, flags | FLAG_RTR, min(size, 8), b"", chan, n)
                else:
                    raise _Bad(f"unknown frame type {kind!r}")
            elif ch == "CANFD":
                full = _fd_frame(tok, base, start + t, n, sink)
            else:
                continue  # "Start of measurement", "CAN 1 Status:..." and other events
        except _Bad as e:
            ctx.problems.add(ctx.source, f"line {n}", str(e))
            continue
        if full:
            yield sink.flush()
    yield from sink.drain()


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
