"""IXXAT MiniMon V3 ASCII trace: quoted, ';'-separated rows after a short header.

No library reads this format. Rows look like
``"00:02:20.66";"83";"Std";"";"00 00 00 01 20 00 00 00 "`` (time, hex id,
Std/Ext, flags such as ``Rtr``, data bytes or ``Remote request  DLC = n``).

Time: the first column counts from when MiniMon started, not from the header's
``Start time`` (in the real trace the rows run from 00:02:20 to 00:03:34 while
the header's start and stop times are 2:28 apart: counted from the start, the
last rows would come after the stop). The trace begins at ``Date`` + ``Start
time`` (local time), so the first row is placed there and the others keep their
distance from it: absolute times, exact to the gap between starting the trace and
its first frame (a bus with heartbeats: milliseconds). Without the header the
times stay relative seconds.
"""

from __future__ import annotations

import datetime
import re
from collections.abc import Iterator
from typing import BinaryIO

from cananalyze.core.frames import FLAG_EXT, FLAG_RTR, FrameBatch
from cananalyze.formats.logs._rows import RowSink, text_lines
from cananalyze.formats.registry import LogFormat, ReadContext, register

_HEADER = b'"Time";"Identifier (hex)"'
_RTR_DLC = re.compile(r"DLC\s*=\s*(\d+)")


class _Bad(Exception):
    pass


def sniff(head: bytes) -> bool:
    return head.startswith(b"ASCII Trace IXXAT") or _HEADER in head[:4096]


def _clock(text: str) -> float:
    """Seconds of ``hh:mm:ss.cc``."""
    parts = text.split(":")
    if len(parts) != 3:
        raise _Bad(f"invalid time {text!r}")
    try:
        return int(parts[0]) * 3600 + int(parts[1]) * 60 + float(parts[2])
    except ValueError:
        raise _Bad(f"invalid time {text!r}") from None


def _row(line: str) -> tuple[float, int, int, int, bytes]:
    fields = [f.strip().strip('"').strip() for f in line.split(";")]
    if len(fields) < 5:
        raise _Bad(f"expected 5 ';'-separated fields, got {len(fields)}")
    t = _clock(fields[0])
    try:
        can_id = int(fields[1], 16)
    except ValueError:
        raise _Bad(f"invalid identifier {fields[1]!r}") from None
    fmt = fields[2].lower()
    if fmt not in ("std", "ext"):
        raise _Bad(f"unknown frame format {fields[2]!r}")
    flags = FLAG_EXT if fmt == "ext" else 0
    if can_id > (0x1FFFFFFF if flags else 0x7FF):
        raise _Bad(f"identifier {fields[1]!r} out of range")
    data_text = fields[4]
    if "rtr" in fields[3].lower():
        m = _RTR_DLC.search(data_text)
        return t, can_id, flags | FLAG_RTR, min(int(m.group(1)), 8) if m else 0, b""
    try:
        data = bytes.fromhex(data_text)
    except ValueError:
        raise _Bad(f"invalid data bytes {data_text!r}") from None
    if len(data) > 8:
        raise _Bad(f"{len(data)} data bytes in a classic CAN frame")
    return t, can_id, flags, len(data), data


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "ixxat"
    sink = RowSink(ctx)
    chan = sink.channel("1")
    date = clock = None
    in_header = True
    shift: float | None = None  # start epoch - the first row's clock, once known
    for n, line in text_lines(stream, ctx=ctx, skip_blank=True):
        if not line.strip():
            continue
        if in_header:
            if line.startswith('"Time"'):
                in_header = False
                if date and clock:
                    try:
                        start = datetime.datetime.strptime(f"{date} {clock}", "%d.%m.%Y %H:%M:%S")
                        ctx.start_time = start.timestamp()
                        ctx.absolute_time = True
                    except ValueError:
                        ctx.problems.add(
                            ctx.source, f"line {n}", f"unreadable header date {date} {clock}"
                        )
            elif line.startswith("Date:"):
                date = line[5:].strip()
            elif line.startswith("Start time:"):
                clock = line[11:].strip()
            continue
        try:
            t, can_id, flags, dlc, data = _row(line)
        except _Bad as e:
            ctx.problems.add(ctx.source, f"line {n}", str(e))
            continue
        if ctx.absolute_time:
            if shift is None:
                shift = ctx.start_time - t
            t += shift
        if sink.add(t, can_id, flags, dlc, data, chan, n):
            yield sink.flush()
    if in_header:
        ctx.problems.add(
            ctx.source, "line 1", 'no "Time";"Identifier (hex)";... column header found'
        )
    yield from sink.drain()


FORMAT = register(
    LogFormat(
        name="ixxat",
        description="IXXAT MiniMon ASCII trace",
        sniff=sniff,
        read=read,
        suffixes=(".trc", ".csv"),
        priority=25,
    )
)
