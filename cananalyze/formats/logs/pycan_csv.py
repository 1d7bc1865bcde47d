"""python-can's CSV log (``can.CSVWriter``): ``timestamp,arbitration_id,extended,remote,error,dlc,data``.

Data is base64. python-can's CSVReader raises on the first bad line; this one
reports the line and goes on. Time stamps are whatever python-can had: Unix
time for captures from a bus (absolute), small numbers for synthetic logs.
"""

from __future__ import annotations

import binascii
from base64 import b64decode
from collections.abc import Iterator
from typing import BinaryIO

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FrameBatch
from cananalyze.formats.logs._rows import RowSink, text_lines
from cananalyze.formats.registry import LogFormat, ReadContext, register

HEADER = "timestamp,arbitration_id,extended,remote,error,dlc,data"


class _Bad(Exception):
    pass


def sniff(head: bytes) -> bool:
    return head.lstrip().startswith(HEADER.encode())


def _flag(text: str, name: str) -> bool:
    if text not in ("0", "1"):
        raise _Bad(f"invalid {name} value {text!r}")
    return text == "1"


def _row(line: str):
    f = line.split(",")
    if len(f) != 7:
        raise _Bad(f"expected 7 fields, got {len(f)}")
    try:
        t = float(f[0])
    except ValueError:
        raise _Bad(f"invalid timestamp {f[0]!r}") from None
    try:
        can_id = int(f[1], 16)
    except ValueError:
        raise _Bad(f"invalid arbitration_id {f[1]!r}") from None
    ext, rtr, err = _flag(f[2], "extended"), _flag(f[3], "remote"), _flag(f[4], "error")
    if not 0 <= can_id <= (0x1FFFFFFF if ext else 0x7FF):
        raise _Bad(f"arbitration_id {f[1]!r} out of range")
    if not f[5].isdecimal() or int(f[5]) > 64:
        raise _Bad(f"invalid dlc {f[5]!r}")
    dlc = int(f[5])
    try:
        data = b64decode(f[6].strip(), validate=True)
    except (binascii.Error, ValueError):
        raise _Bad(f"invalid base64 data {f[6].strip()!r}") from None
    if len(data) > 64:
        raise _Bad(f"{len(data)} data bytes")
    flags = (FLAG_EXT if ext else 0) | (FLAG_RTR if rtr else 0) | (FLAG_ERR if err else 0)
    if len(data) > 8:
        flags |= FLAG_FD
    size = min(dlc, 64) if rtr else len(data)
    return t, can_id, flags, size, data


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "pycan_csv"
    sink = RowSink(ctx, epoch_times=True)
    chan = sink.channel("1")
    header = True
    for n, line in text_lines(stream, ctx=ctx, skip_blank=True):
        if header:  # line 1 (a blank line 1, skipped, is no header either)
            header = False
            if n != 1 or line.strip() != HEADER:
                ctx.problems.add(ctx.source, "line 1", "not a python-can CSV header")
                return
            continue
        if not line.strip():
            continue
        try:
            t, can_id, flags, size, data = _row(line)
        except _Bad as e:
            ctx.problems.add(ctx.source, f"line {n}", str(e))
            continue
        if sink.add(t, can_id, flags, size, data, chan, n):
            yield sink.flush()
    yield from sink.drain()


FORMAT = register(
    LogFormat(
        name="pycan_csv",
        description="python-can CSV log",
        sniff=sniff,
        read=read,
        suffixes=(".csv",),
        priority=41,
    )
)
