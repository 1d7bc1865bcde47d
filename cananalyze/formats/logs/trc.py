"""PEAK PCAN trace (.trc) versions 1.0, 1.1, 1.3, 2.0 and 2.1.

python-can's TRCReader understands the same versions but builds a Message per
frame and drops unreadable lines with only a log message; this reader follows its
column rules (column layout per version, ``$COLUMNS`` for 2.x, ID width decides
extended, Rx/Tx, RR remote, FD/FB/FE/BI types) while streaming rows into columns
and reporting bad lines with their line number.

Time: offsets in ms from ``$STARTTIME`` (days since 1899-12-30; taken as UTC,
as python-can does). Version 1.0 has no start time, so times stay relative.
Status lines (``Warng``, ``ST``, ``EC``, ``ER``, ``EV``, bus-info id FFFFFFFF)
are not frames and are skipped silently.
"""

from __future__ import annotations

import datetime
import math
import re
from collections.abc import Iterator
from typing import BinaryIO

from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
)
from cananalyze.formats.logs._rows import RowSink, text_lines
from cananalyze.formats.registry import LogFormat, ReadContext, register

_DLC2LEN = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
_EPOCH_1899 = datetime.datetime(1899, 12, 30, tzinfo=datetime.UTC)
_V1_LINE = re.compile(rb"(?m)^[ \t]*\d+\)\s+\d+(\.\d+)?\s+")
_FD_TYPES = {"FD": 0, "FB": FLAG_BRS, "FE": FLAG_BRS | FLAG_ESI, "BI": FLAG_ESI}
_SKIP_TYPES = {"ST", "EC", "ER", "EV", "Warng", "Error", "Event"}


class _Bad(Exception):
    pass


def sniff(head: bytes) -> bool:
    if head.startswith(b";$FILEVERSION"):
        return True
    if not head.startswith(b";"):
        return False
    # version 1.0 has no $FILEVERSION: a ';' comment block then "   1)  17535  ..." rows
    return _V1_LINE.search(head) is not None and b"@ TEXT @" not in head[:64]


def _hex_bytes(toks: list[str], n: int) -> bytes:
    if len(toks) < n:
        raise _Bad(f"frame says {n} data bytes but has {len(toks)}")
    try:
        out = bytes.fromhex(" ".join(toks[:n]))
    except ValueError:
        raise _Bad(f"invalid data bytes {' '.join(toks[:n])!r}") from None
    if len(out) != n:
        raise _Bad(f"invalid data bytes {' '.join(toks[:n])!r}")
    return out


def _ident(text: str) -> tuple[int, int]:
    try:
        can_id = int(text, 16)
    except ValueError:
        raise _Bad(f"invalid identifier {text!r}") from None
    ext = len(text) > 4
    if can_id > (0x1FFFFFFF if ext else 0x7FF):
        raise _Bad(f"identifier {text!r} out of range")
    return can_id, FLAG_EXT if ext else 0


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _Bad(f"invalid {what} {text!r}") from None
    if not math.isfinite(value):
        raise _Bad(f"invalid {what} {text!r}")
    return value


def _dlc(text: str) -> int:
    # isdecimal, not isdigit: isdigit() accepts '³', which int() refuses
    if not text.isdecimal() or int(text) > 15:
        raise _Bad(f"invalid DLC {text!r}")
    return int(text)


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "trc"
    sink = RowSink(ctx)
    version = "1.0"
    start = 0.0
    columns: dict[str, int] = {}
    in_header = True
    for n, line in text_lines(stream, ctx=ctx, skip_blank=True):
        s = line.strip()
        if not s:
            continue
        if s.startswith(";"):
            if in_header and s.startswith(";$"):
                key, _, value = s[2:].partition("=")
                if key == "FILEVERSION":
                    version = value.strip()
                elif key == "STARTTIME":
                    try:
                        days = float(value)
                        start = (_EPOCH_1899 + datetime.timedelta(days=days)).timestamp()
                    except (ValueError, OverflowError):  # not a number, NaN, or beyond year 9999
                        ctx.problems.add(ctx.source, f"line {n}", f"invalid $STARTTIME {value!r}")
                        continue
                    ctx.absolute_time = True
                    ctx.start_time = start
                elif key == "COLUMNS":
                    columns = {c.strip(): i for i, c in enumerate(value.split(","))}
            continue
        if in_header:
            in_header = False
            if version not in ("1.0", "1.1", "1.2", "1.3", "2.0", "2.1"):
                ctx.problems.add(ctx.source, f"line {n}", f"unsupported TRC version {version}")
                return
            if version.startswith("2") and not {"O", "T", "I", "d"} <= columns.keys():
                ctx.problems.add(ctx.source, f"line {n}", "TRC 2.x without usable $COLUMNS")
                return
        try:
            if version.startswith("2"):
                row = _row_v2(s, columns)
            else:
                row = _row_v1(s, version)
        except _Bad as e:
            ctx.problems.add(ctx.source, f"line {n}", str(e))
            continue
        if row is None:
            continue
        t, can_id, flags, dlc, data, bus = row
        if sink.add(start + t, can_id, flags, dlc, data, sink.channel(bus), n):
            yield sink.flush()
    yield from sink.drain()


def _row_v1(s: str, version: str):
    tok = s.split()
    if len(tok) < 4 or not tok[0].endswith(")"):
        raise _Bad(f"not a TRC {version} frame line: {s[:60]!r}")
    t = _number(tok[1], "time offset") / 1000.0
    bus = "1"
    flags = 0
    if version == "1.0":
        i = 2
    elif version == "1.3":  # N) O bus Rx/Tx id - dlc data
        bus = tok[2]
        kind = tok[3]
        if kind in _SKIP_TYPES:
            return None
        if kind not in ("Rx", "Tx"):
            raise _Bad(f"unknown message type {kind!r}")
        flags = FLAG_TX if kind == "Tx" else 0
        i = 4
    else:  # 1.1, 1.2: N) O Rx/Tx id dlc data
        kind = tok[2]
        if kind in _SKIP_TYPES:
            return None
        if kind not in ("Rx", "Tx"):
            raise _Bad(f"unknown message type {kind!r}")
        flags = FLAG_TX if kind == "Tx" else 0
        i = 3
    if len(tok) <= i:
        raise _Bad(f"not a TRC {version} frame line: {s[:60]!r}")
    if tok[i] == "FFFFFFFF":
        return None  # bus status information, not a frame
    can_id, ext = _ident(tok[i])
    j = i + 2 if version == "1.3" else i + 1
    if len(tok) <= j:
        raise _Bad("missing DLC")
    dlc = _dlc(tok[j])
    rest = tok[j + 1 :]
    if rest[:1] == ["RTR"]:
        return t, can_id, flags | ext | FLAG_RTR, min(dlc, 8), b"", bus
    size = min(dlc, 8)
    return t, can_id, flags | ext, size, _hex_bytes(rest, size), bus


def _row_v2(s: str, col: dict[str, int]):
    tok = s.split()
    need = max(col["O"], col["T"], col["I"], col["d"])
    if len(tok) <= need:
        raise _Bad(f"not a TRC 2.x frame line: {s[:60]!r}")
    kind = tok[col["T"]]
    if kind in _SKIP_TYPES:
        return None
    if kind != "DT" and kind != "RR" and kind not in _FD_TYPES:
        raise _Bad(f"unknown message type {kind!r}")
    t = _number(tok[col["O"]], "time offset") / 1000.0
    can_id, flags = _ident(tok[col["I"]])
    direction = tok[col["d"]]
    if direction not in ("Rx", "Tx"):
        raise _Bad(f"invalid direction {direction!r}")
    if direction == "Tx":
        flags |= FLAG_TX
    bus = tok[col["B"]] if "B" in col and col["B"] < len(tok) else "1"
    if "l" in col:
        text = tok[col["l"]] if len(tok) > col["l"] else ""
        if not text.isdecimal() or int(text) > 64:
            raise _Bad(f"invalid length {text!r}")
        size = int(text)
    elif "L" in col:
        code = _dlc(tok[col["L"]] if len(tok) > col["L"] else "")
        size = _DLC2LEN[code] if kind in _FD_TYPES else min(code, 8)
    else:
        raise _Bad("no length column")
    if kind in _FD_TYPES:
        flags |= FLAG_FD | _FD_TYPES[kind]
    if kind == "RR":
        return t, can_id, flags | FLAG_RTR, size, b"", bus
    data = _hex_bytes(tok[col["D"] :] if "D" in col else [], size) if size else b""
    return t, can_id, flags, size, data, bus


FORMAT = register(
    LogFormat(
        name="trc",
        description="PEAK PCAN trace",
        sniff=sniff,
        read=read,
        suffixes=(".trc",),
        priority=32,
    )
)
