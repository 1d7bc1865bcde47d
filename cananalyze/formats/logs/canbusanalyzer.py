"""CAN bus analyzer ``.trc`` text export (``@ TEXT @ ...`` header), as in SavvyCAN's examples.

Not a PEAK trace despite the suffix. The header line is ``@``-separated and its
fifth field is the number of frames; rows are tab-separated, CR-terminated:
``time(s, decimal comma)  1  0004  ID(hex)  DLC  data bytes  00000000  ascii``.
The second and third columns (always ``1`` and ``0004`` in the known file) are
not documented and are ignored; the frame count in the header is checked.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from typing import BinaryIO

from cananalyze.core.frames import FLAG_EXT, FrameBatch
from cananalyze.formats.logs._rows import RowSink, text_lines
from cananalyze.formats.registry import LogFormat, ReadContext, register


class _Bad(Exception):
    pass


def sniff(head: bytes) -> bool:
    return head.startswith(b"@ TEXT @")


def _row(line: str):
    f = line.split("\t")
    if len(f) < 6:
        raise _Bad(f"expected tab-separated fields, got {len(f)}")
    try:
        t = float(f[0].strip().replace(",", "."))
    except ValueError:
        raise _Bad(f"invalid time {f[0]!r}") from None
    try:
        can_id = int(f[3], 16)
    except ValueError:
        raise _Bad(f"invalid identifier {f[3]!r}") from None
    if can_id > 0x1FFFFFFF:
        raise _Bad(f"identifier {f[3]!r} out of range")
    if not f[4].strip().isdecimal() or int(f[4]) > 8:
        raise _Bad(f"invalid DLC {f[4]!r}")
    dlc = int(f[4])
    try:
        data = bytes.fromhex(f[5])
    except ValueError:
        raise _Bad(f"invalid data bytes {f[5]!r}") from None
    if len(data) < dlc:
        raise _Bad(f"DLC {dlc} but {len(data)} data bytes")
    return t, can_id, FLAG_EXT if can_id > 0x7FF else 0, dlc, data[:dlc]


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "canbusanalyzer"
    sink = RowSink(ctx)
    chan = sink.channel("1")
    text = io.TextIOWrapper(stream, encoding="latin-1", newline=None)  # CR line ends
    declared = None
    rows = 0
    for n, line in text_lines(text, ctx=ctx, skip_blank=True):
        if n == 1:
            fields = [x.strip() for x in line.split("@")]
            if len(fields) > 5 and fields[5].isdecimal():
                declared = int(fields[5])
            continue
        if not line.strip():
            continue
        rows += 1
        try:
            t, can_id, flags, dlc, data = _row(line)
        except _Bad as e:
            ctx.problems.add(ctx.source, f"line {n}", str(e))
            continue
        if sink.add(t, can_id, flags, dlc, data, chan, n):
            yield sink.flush()
    text.detach()
    if declared is not None and declared != rows:
        ctx.problems.add(ctx.source, "line 1", f"header says {declared} frames, file has {rows}")
    yield from sink.drain()


FORMAT = register(
    LogFormat(
        name="canbusanalyzer",
        description="CAN bus analyzer text trace (@ TEXT @)",
        sniff=sniff,
        read=read,
        suffixes=(".trc",),
        priority=20,
    )
)
