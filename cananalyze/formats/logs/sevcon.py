"""Sevcon DVT ``can_cli_dump`` text: ``0xID  time  -  d<delta>  0  name  { 0xB0 0xB1 ... }``.

Written by Sevcon's DVT tool; no library reads it. Time is in units of 0.1 ms.
Frames without braces carry no data bytes (SYNC). EMCY lines hold DVT's decoded
text, not the bytes (``0x0081 ... EMCY Mains Voltage. Sevcon code: 0x45C5``): the
frame is rebuilt from what the line says, the CiA 301 error class as the error code
(its class base: 0x3100 for "Mains Voltage"), the error register's generic bit set
for every error (CiA 301 says it is) and clear for "Error Reset", and the Sevcon
code in manufacturer bytes 3-4 (little-endian; the other bytes are not in the dump,
so zero). Such a frame carries FLAG_RECONSTRUCTED: the outputs mark it, its bytes were
not captured. A line whose class or code cannot be read stays a counted problem.

Frames DVT sent itself are logged with time 0 (and a meaningless negative
delta); they are marked FLAG_TX and given the time of the frame before them so
the log stays in time order.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from typing import BinaryIO

from cananalyze.core.frames import FLAG_RECONSTRUCTED, FLAG_TX, FrameBatch
from cananalyze.formats.logs._rows import RowSink, text_lines
from cananalyze.formats.registry import LogFormat, ReadContext, register

_LINE = re.compile(rb"(?m)^0x[0-9A-Fa-f]{1,8}\s+\d+\s+-\s+d\s*-?[\d.]+\s+\d+\s+\S+")
_ROW = re.compile(r"^0x([0-9A-Fa-f]{1,8})\s+(\d+)\s+\S*\s+d\s*(-?[\d.]+)\s+(\d+)\s+(\S+)(.*)$")


_EMCY = re.compile(r"^(.+?)\.\s+Sevcon code:\s*0x([0-9A-Fa-f]{1,4})$")


def _emcy(text: str) -> bytes | None:
    """The 8 EMCY bytes a DVT line stands for (see the module docstring), or None."""
    from cananalyze.protocol.emcy import ERROR_CLASSES

    m = _EMCY.match(text)
    if m is None:
        return None
    wanted = m.group(1).strip().lower()
    code = next((c for c, name in ERROR_CLASSES.items() if name.lower() == wanted), None)
    if code is None:
        return None
    register = 0x00 if code == 0 else 0x01
    return (
        code.to_bytes(2, "little")
        + bytes([register])
        + int(m.group(2), 16).to_bytes(2, "little")
        + bytes(3)
    )


def sniff(head: bytes) -> bool:
    return len(_LINE.findall(head[:16384])) >= 3


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "sevcon"
    sink = RowSink(ctx)
    chan = sink.channel("1")
    last_t = 0.0
    for n, line in text_lines(stream, ctx=ctx, skip_blank=True):
        s = line.strip()
        if not s:
            continue
        m = _ROW.match(s)
        if m is None:
            ctx.problems.add(ctx.source, f"line {n}", f"not a DVT dump line: {s[:60]!r}")
            continue
        can_id = int(m.group(1), 16)
        if can_id > 0x7FF:
            ctx.problems.add(ctx.source, f"line {n}", f"identifier 0x{m.group(1)} out of range")
            continue
        if len(m.group(2)) > 15:  # beyond float precision (and int * 1e-4 overflows)
            ctx.problems.add(ctx.source, f"line {n}", f"time {m.group(2)[:20]!r} out of range")
            continue
        ticks = int(m.group(2))
        rest = m.group(6).strip()
        rebuilt = 0
        if rest.startswith("{"):
            if not rest.endswith("}"):
                ctx.problems.add(ctx.source, f"line {n}", "data bytes without closing '}'")
                continue
            cells = rest[1:-1].split()
            try:
                data = bytes(int(c, 16) for c in cells)
            except ValueError:
                ctx.problems.add(ctx.source, f"line {n}", f"invalid data bytes {rest!r}")
                continue
            if len(data) > 8 or not all(c.lower().startswith("0x") for c in cells):
                ctx.problems.add(ctx.source, f"line {n}", f"invalid data bytes {rest!r}")
                continue
        elif m.group(5) == "EMCY" and (emcy := _emcy(rest)) is not None:
            data = emcy
            rebuilt = FLAG_RECONSTRUCTED
        elif rest:
            ctx.problems.add(
                ctx.source, f"line {n}", f"{m.group(5)} shown as decoded text only, no raw bytes"
            )
            continue
        else:
            data = b""
        flags = rebuilt
        if ticks == 0 and last_t > 0:
            flags |= FLAG_TX
            t = last_t
        else:
            t = last_t = ticks * 1e-4
        if sink.add(t, can_id, flags, len(data), data, chan, n):
            yield sink.flush()
    yield from sink.drain()


FORMAT = register(
    LogFormat(
        name="sevcon",
        description="Sevcon DVT can_cli_dump text",
        sniff=sniff,
        read=read,
        suffixes=(".txt",),
        priority=45,
    )
)
