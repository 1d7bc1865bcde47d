"""Any log python-can can read (by suffix) that no fast reader here claims: SQLite, ...

This path is per message by necessity (python-can yields one Message at a
time); it exists for coverage of rare formats, not for speed. Messages are
copied into RowSink columns, so memory still stays bounded per batch.
"""

from __future__ import annotations

import io
import os
from collections.abc import Iterator
from pathlib import PurePath
from typing import BinaryIO

from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
)
from cananalyze.formats.logs._rows import RowSink
from cananalyze.formats.registry import LogFormat, ReadContext, register

# python-can's MESSAGE_READERS less the formats read here (checked by a test), written
# out so that importing the readers does not import python-can
PYCAN_ONLY_SUFFIXES = (".db",)
_MAGIC = (b"SQLite format 3\x00",)


def sniff(head: bytes) -> bool:
    """Formats only python-can reads: python-can's SQLite logs (MF4 is formats/logs/mf4.py)."""
    return head.startswith(_MAGIC)


def _suffix(ctx: ReadContext, head: bytes) -> str:
    if head.startswith(_MAGIC[0]):
        return ".db"
    path = PurePath(ctx.source)
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes.pop()
    return suffixes[-1] if suffixes else ""


def _open(cls, stream: BinaryIO, ctx: ReadContext):
    from can.io.generic import BinaryIOMessageReader, TextIOMessageReader

    if issubclass(cls, BinaryIOMessageReader):
        return cls(stream)
    if issubclass(cls, TextIOMessageReader):
        text = io.TextIOWrapper(stream, encoding="latin-1", newline=None)
        if cls.__name__ == "ASCReader":  # times from the header date, as the ASC reader gives
            return cls(text, relative_timestamp=False)
        return cls(text)
    if os.path.isfile(ctx.source):  # SQLite needs a real file
        return cls(ctx.source)
    raise ValueError(f"python-can's {cls.__name__} needs a file on disk")


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    from can.io.player import MESSAGE_READERS  # python-can takes ~70 ms to import: only here

    head = stream.peek(16)[:16] if hasattr(stream, "peek") else b""
    suffix = _suffix(ctx, head)
    cls = MESSAGE_READERS.get(suffix)
    ctx.format = f"python-can{suffix}"
    if cls is None:
        ctx.problems.add(ctx.source, "line 1", f"unknown log format (suffix {suffix or 'none'!r})")
        return
    try:
        reader = _open(cls, stream, ctx)
    except Exception as e:  # python-can raises many kinds (ImportError for asammdf, ...)
        ctx.problems.add(ctx.source, "record 1", f"python-can {cls.__name__} cannot open it: {e}")
        return
    sink = RowSink(ctx, epoch_times=True)
    k = 0
    try:
        for k, m in enumerate(reader, 1):
            data = bytes(m.data or b"")
            flags = (
                (FLAG_EXT if m.is_extended_id else 0)
                | (FLAG_RTR if m.is_remote_frame else 0)
                | (FLAG_ERR if m.is_error_frame else 0)
                | (FLAG_FD if m.is_fd else 0)
                | (FLAG_BRS if m.bitrate_switch else 0)
                | (FLAG_ESI if m.error_state_indicator else 0)
                | (0 if m.is_rx else FLAG_TX)
            )
            size = min(m.dlc, 64) if m.is_remote_frame else len(data)
            chan = sink.channel("1" if m.channel is None else str(m.channel))
            if sink.add(m.timestamp, m.arbitration_id, flags, size, data, chan, k):
                yield sink.flush()
    except Exception as e:
        ctx.problems.add(ctx.source, f"record {k + 1}", f"python-can {cls.__name__}: {e}")
    finally:
        stop = getattr(reader, "stop", None)
        if stop:
            stop()
    yield from sink.drain()


FORMAT = register(
    LogFormat(
        name="pycan",
        description="any other format python-can reads (SQLite, ...)",
        sniff=sniff,
        read=read,
        suffixes=PYCAN_ONLY_SUFFIXES,
        priority=90,
        text=False,
    )
)
