"""SavvyCAN / GVRET CSV logs: ``Time Stamp,ID,Extended,[Dir,]Bus,LEN,D1,...``.

SavvyCAN's native save format; python-can has no reader for it. Columns are
found by header name, so the variant with a ``Dir`` column and logs with more
than eight data columns (CAN FD) read too. Time stamps are microseconds, from
the interface's clock (relative) unless they are large enough to be Unix time.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import BinaryIO

from cananalyze.core.frames import FLAG_EXT, FLAG_FD, FLAG_TX, FrameBatch
from cananalyze.formats.logs._rows import RowSink, text_lines
from cananalyze.formats.registry import LogFormat, ReadContext, register


class _Bad(Exception):
    pass


def sniff(head: bytes) -> bool:
    first = head.split(b"\n", 1)[0].strip().lower()
    return first.startswith(b"time stamp,id,extended,")


def _row(f: list[str], col: dict[str, int], first_data: int):
    try:
        t = float(f[col["time stamp"]]) / 1e6
    except ValueError:
        raise _Bad(f"invalid time stamp {f[col['time stamp']]!r}") from None
    try:
        can_id = int(f[col["id"]], 16)
    except ValueError:
        raise _Bad(f"invalid identifier {f[col['id']]!r}") from None
    ext = f[col["extended"]].strip().lower()
    if ext not in ("true", "false", "1", "0"):
        raise _Bad(f"invalid Extended value {f[col['extended']]!r}")
    flags = FLAG_EXT if ext in ("true", "1") else 0
    if can_id > (0x1FFFFFFF if flags else 0x7FF):
        raise _Bad(f"identifier {f[col['id']]!r} out of range")
    if "dir" in col and f[col["dir"]].strip().lower() == "tx":
        flags |= FLAG_TX
    bus = f[col["bus"]].strip() if "bus" in col else "0"
    size_text = f[col["len"]].strip()
    if not size_text.isdecimal() or int(size_text) > 64:
        raise _Bad(f"invalid LEN {size_text!r}")
    size = int(size_text)
    cells = [c.strip() for c in f[first_data : first_data + size]]
    if len(cells) < size or not all(cells):
        raise _Bad(f"LEN {size} but only {len([c for c in cells if c])} data bytes")
    try:
        data = bytes(int(c, 16) for c in cells)
    except ValueError:
        raise _Bad(f"invalid data byte in {','.join(cells)!r}") from None
    if any(b > 255 for b in data):
        raise _Bad("data byte out of range")
    if size > 8:
        flags |= FLAG_FD
    return t, can_id, flags, size, data, bus


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "gvret"
    sink = RowSink(ctx, epoch_times=True)
    col: dict[str, int] = {}
    first_data = 0
    for n, line in text_lines(stream, ctx=ctx, skip_blank=True):
        if not line.strip():
            continue
        f = line.split(",")
        if not col:
            col = {name.strip().lower(): i for i, name in enumerate(f)}
            if not {"time stamp", "id", "extended", "len"} <= col.keys() or "d1" not in col:
                ctx.problems.add(ctx.source, f"line {n}", "not a GVRET CSV header")
                return
            first_data = col["d1"]
            continue
        try:
            if len(f) < first_data:
                raise _Bad(f"expected at least {first_data + 1} fields, got {len(f)}")
            t, can_id, flags, size, data, bus = _row(f, col, first_data)
        except _Bad as e:
            ctx.problems.add(ctx.source, f"line {n}", str(e))
            continue
        if sink.add(t, can_id, flags, size, data, sink.channel(bus), n):
            yield sink.flush()
    yield from sink.drain()


FORMAT = register(
    LogFormat(
        name="gvret",
        description="SavvyCAN/GVRET CSV log",
        sniff=sniff,
        read=read,
        suffixes=(".csv",),
        priority=40,
    )
)
