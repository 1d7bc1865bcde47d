"""ASAM MDF4 (.mf4) bus logging: the CAN_DataFrame, CAN_RemoteFrame and CAN_ErrorFrame
channel groups that CANedge loggers, Vector and Kvaser tools write.

asammdf (the `mf4` extra) parses the blocks, unsorted and compressed (DZ) data and
finalises an unfinalised file (`UnFinMF`) in a temporary copy, never in the file
itself. Each bus-logging group's fields (ID, IDE, DLC, DataLength, DataBytes,
BusChannel, Dir, EDL, BRS, ESI) are read as numpy columns with one `select` per
chunk of CHUNK records, so a file of ten million frames never holds all its arrays
at once; the groups are merged by time, as a logger interleaves them. Time is the
header's start (nanoseconds since 1970, UTC; a header in local time is taken as
UTC, the file does not say its zone) plus the master channel; a bus is named by
its BusChannel number ("1", "2", ...), as BLF names its channels.

Damage is reported, not raised: a file asammdf cannot open is one problem naming
it and what was wrong (then "no frame could be read", exit 2); a group whose
records cannot be read keeps the chunks before; a record whose DataLength is more
than its DataBytes hold is left out, never made a frame.
"""

from __future__ import annotations

import gc
import io
import logging
import shutil
import struct
import sys
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import BinaryIO

import numpy as np

from cananalyze.core.extras import need
from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
    channel_index,
)
from cananalyze.formats.registry import LogFormat, ReadContext, register

MAGICS = (b"MDF     ", b"UnFinMF ")
KINDS = {"CAN_DataFrame": 0, "CAN_RemoteFrame": FLAG_RTR, "CAN_ErrorFrame": FLAG_ERR}
FIELDS = ("ID", "IDE", "DLC", "DataLength", "DataBytes", "BusChannel", "Dir", "EDL", "BRS", "ESI")
CHUNK = 1 << 16  # records of one group read at once: ~50 MB at its peak (64-byte DataBytes)
# a compressed (DZ) block's inflated size: asammdf writes 4 MiB, loggers less
MAX_INFLATED = 256 << 20
ID_EXT_BIT = 0x80000000  # some writers mark a 29-bit identifier in ID's top bit
ID_MASK = 0x1FFFFFFF
FD_LENGTHS = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64], np.int64)


def sniff(head: bytes) -> bool:
    """MDF files start with "MDF     " (an unfinalised one "UnFinMF ") and the version."""
    return head[:8] in MAGICS and head[8:9].isdigit()


class _Odd(ValueError):
    """A field whose column is no CAN field (its type or shape), named in the message."""


@dataclass
class _Group:
    """A bus-logging channel group: its index, frame kind and field -> (channel index)."""

    index: int
    kind: str
    fields: dict[str, tuple[str, int]]
    records: int
    source: str  # the acquisition source's name ("" when none)
    done: int = 0  # records read so far


@dataclass
class _Rows:
    """Frames of one chunk of one group, in record order."""

    t: np.ndarray
    can_id: np.ndarray
    flags: np.ndarray
    dlc: np.ndarray
    data: np.ndarray  # (n, 8)
    channel: np.ndarray
    line: np.ndarray
    long: dict[int, bytes] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    def take(self, idx: np.ndarray | slice) -> _Rows:
        """Rows by boolean mask, index array or slice (long payloads renumbered)."""
        long = {}
        if self.long:
            rows = np.arange(len(self))[idx]
            new = np.full(len(self), -1, np.int64)
            new[rows] = np.arange(len(rows))
            long = {int(new[k]): v for k, v in self.long.items() if new[k] >= 0}
        return _Rows(*(getattr(self, f)[idx] for f in _COLUMNS), long=long)


def _concat(parts: list[_Rows]) -> _Rows:
    long: dict[int, bytes] = {}
    offset = 0
    for p in parts:
        long.update({k + offset: v for k, v in p.long.items()})
        offset += len(p)
    return _Rows(*(np.concatenate([getattr(p, f) for p in parts]) for f in _COLUMNS), long=long)


_COLUMNS = ("t", "can_id", "flags", "dlc", "data", "channel", "line")


class _Reader:
    """The bus-logging groups of one opened MDF, read a chunk at a time and merged."""

    def __init__(self, mdf, ctx: ReadContext) -> None:
        self.mdf = mdf
        self.ctx = ctx
        self.names: list[str] = []
        self._name_index: dict[str, int] = {}
        self.start = 0.0

    def problem(self, where: str, text: str) -> None:
        self.ctx.problems.add(self.ctx.source, where, text)

    def groups(self) -> list[_Group]:
        """The CAN bus-logging groups, empty ones too (a log with no frames is no failure);
        any writer's: found by the `<kind>.ID` channel, with or without a prefix."""
        found = []
        for gi, group in enumerate(self.mdf.groups):
            fields: dict[str, tuple[str, int]] = {}
            kinds = set()
            for ci, ch in enumerate(group.channels):
                parts = ch.name.split(".")
                if len(parts) >= 2 and parts[-2] in KINDS and parts[-1] in FIELDS:
                    kinds.add(parts[-2])
                    fields.setdefault(parts[-1], (ch.name, ci))
            if len(kinds) != 1 or "ID" not in fields:
                continue
            cg = group.channel_group
            # a group with no records has none to read or lose (CANedge writes every
            # bus's groups, its FD ones with their data in a VLSD group, empty or not)
            outside = _outside(group.channels, int(cg.samples_byte_nr)) if cg.cycles_nr else ""
            if outside:
                self.problem(
                    f"group {gi}",
                    f"{outside}: the file is corrupt, its {cg.cycles_nr} records are skipped",
                )
                continue
            big = max((int(b.original_size) for b in group.data_blocks if b.block_type), default=0)
            if big > MAX_INFLATED:  # asammdf inflates a block whole, into what it claims
                self.problem(
                    f"group {gi}",
                    f"a compressed data block claims {big:,} bytes inflated (more than "
                    f"{MAX_INFLATED:,}): refused, its {cg.cycles_nr} records are skipped",
                )
                continue
            source = getattr(cg, "acq_source", None)
            name = (getattr(source, "name", "") or "") if source is not None else ""
            found.append(_Group(gi, kinds.pop(), fields, int(cg.cycles_nr), str(name)))
        return found

    def chunk(self, g: _Group) -> _Rows | None:
        """The next CHUNK records of a group as frames; None at its end or on damage."""
        if g.done >= g.records:
            return None
        count = min(CHUNK, g.records - g.done)
        names = list(g.fields)
        try:
            with _quiet():
                signals = self.mdf.select(
                    [(None, g.index, g.fields[f][1]) for f in names],
                    record_offset=g.done,
                    record_count=count,
                    raw=True,
                )
                cols = {f: _values(f, s) for f, s in zip(names, signals, strict=True)}
        except Exception as exc:  # asammdf raises many kinds on damaged blocks or conversions
            self.problem(
                f"group {g.index} record {g.done + 1}",
                f"{g.kind} records cannot be read ({_say(exc)}); the rest of the group is skipped",
            )
            g.done = g.records
            return None
        first = g.done
        t = np.asarray(signals[0].timestamps)
        if t.ndim != 1 or t.dtype.kind not in "iuf":
            self.problem(f"group {g.index}", f"{g.kind} has no usable master (time) channel")
            g.done = g.records
            return None
        t = t.astype(np.float64)
        n = min([len(t)] + [len(c) for c in cols.values()])
        g.done += count
        if n < count:
            self.problem(
                f"group {g.index} record {first + n + 1}",
                f"{g.kind} group ends after {first + n} of its {g.records} records (cut off?)",
            )
            g.done = g.records
        if n == 0:
            return None
        try:
            return self.frames(g, cols, t[:n], first, n)
        except _Odd as exc:
            self.problem(
                f"group {g.index}",
                f"{g.kind}.{exc}: the file is corrupt or not bus logging; "
                f"its {g.records} records are skipped",
            )
            g.done = g.records
            return None

    def frames(self, g: _Group, cols: dict, t: np.ndarray, first: int, n: int) -> _Rows:
        def col(name: str, default: int = 0) -> np.ndarray:
            c = cols.get(name)
            if c is None:
                return np.full(n, default, np.int64)
            c = np.asarray(c[:n])
            if c.ndim != 1 or c.dtype.kind not in "biufSU":
                raise _Odd(f"{name} is {c.dtype} of shape {c.shape[1:]}, not a number a record")
            if c.dtype.kind in "SU":  # a Dir written as text ("Rx"/"Tx")
                return (np.char.strip(c.astype("U")) == "Tx").astype(np.int64)
            if c.dtype.kind == "f" and not (np.abs(c) < 2**32).all():  # NaN fails too
                raise _Odd(f"{name} holds values that are no CAN field's")
            return c.astype(np.int64)

        raw_id = col("ID")
        ext = (raw_id & ID_EXT_BIT) != 0
        if "IDE" in cols:
            ext |= col("IDE") != 0
        fd = col("EDL") != 0
        flags = np.full(n, KINDS[g.kind], np.uint8)
        flags |= np.where(ext, FLAG_EXT, 0).astype(np.uint8)
        flags |= np.where(fd, FLAG_FD, 0).astype(np.uint8)
        flags |= np.where(col("BRS") != 0, FLAG_BRS, 0).astype(np.uint8)
        flags |= np.where(col("ESI") != 0, FLAG_ESI, 0).astype(np.uint8)
        flags |= np.where(col("Dir") != 0, FLAG_TX, 0).astype(np.uint8)
        code = np.clip(col("DLC"), 0, 15)
        from_dlc = np.where(fd, FD_LENGTHS[code], np.minimum(code, 8))
        payload = _bytes(cols.get("DataBytes"), n)
        if g.kind == "CAN_RemoteFrame":  # no data bytes: the length asked for, by its DLC
            length = from_dlc if "DLC" in cols else np.minimum(col("DataLength"), 64)
            payload = np.zeros((n, 0), np.uint8)
            keep = length >= 0
        else:
            length = col("DataLength") if "DataLength" in cols else from_dlc
            keep = (length >= 0) & (length <= min(64, payload.shape[1]))
        timed = np.isfinite(t)
        if not timed.all():
            row = int(np.flatnonzero(~timed)[0])
            self.problem(
                f"group {g.index} record {first + row + 1}",
                f"{int(n - timed.sum())} {g.kind} record(s) whose time is not a number left out",
            )
        if not keep.all():
            row = int(np.flatnonzero(~keep)[0])
            self.problem(
                f"group {g.index} record {first + row + 1}",
                f"{int(n - keep.sum())} {g.kind} record(s) with a DataLength beyond their "
                f"DataBytes ({int(length[row])} > {payload.shape[1]}) left out",
            )
        keep &= timed
        t = np.where(timed, t, 0.0)
        bad = int(n - np.count_nonzero(keep))
        line = np.arange(first + 1, first + n + 1, dtype=np.int64)
        data = np.zeros((n, 8), np.uint8)
        width = min(8, payload.shape[1])
        if width and g.kind != "CAN_RemoteFrame":
            data[:, :width] = payload[:, :width]
            data[np.arange(8)[None, :] >= length[:, None]] = 0
        long = {}
        for i in np.flatnonzero(keep & (length > 8)).tolist():
            long[i] = payload[i, : int(length[i])].tobytes()
        if "BusChannel" in cols:
            bus = col("BusChannel")
            chan = np.zeros(n, np.uint16)
            for b in np.unique(bus).tolist():
                chan[bus == b] = channel_index(self.names, self._name_index, str(b))
        else:
            chan = np.full(
                n, channel_index(self.names, self._name_index, g.source or "1"), np.uint16
            )
        rows = _Rows(
            self.start + t,
            (raw_id & ID_MASK).astype(np.uint32),
            flags,
            np.clip(length, 0, 64).astype(np.uint8),
            data,
            chan,
            line,
            long,
        )
        return rows if not bad else rows.take(np.flatnonzero(keep))

    def batches(self) -> Iterator[FrameBatch]:
        """Every group's frames merged by time, in batches of ctx.batch_size."""
        groups = self.groups()
        if not groups:
            self.problem("offset 0", self._no_can())
            return
        waiting: dict[int, _Rows] = {}  # group -> rows read and not yet given out
        live = list(range(len(groups)))
        ready: list[_Rows] = []
        size = 0
        while live or waiting:
            for k in list(live):
                if k in waiting and len(waiting[k]):
                    continue
                rows = self.chunk(groups[k])
                if rows is None:
                    live.remove(k)
                elif len(rows):
                    waiting[k] = rows
            if not waiting:
                break
            # every row up to the earliest "last time read" of the groups still being read
            # can go: no later chunk of theirs comes before it (records are in time order)
            stop = min((float(waiting[k].t[-1]) for k in live if k in waiting), default=np.inf)
            parts = []
            for k in list(waiting):
                rows = waiting[k]
                if float(rows.t[-1]) <= stop:  # the group that set `stop` always goes whole
                    parts.append(rows)
                    del waiting[k]
                    continue
                early = rows.t <= stop
                if early.any():
                    parts.append(rows.take(early))
                    waiting[k] = rows.take(~early)
            if not parts:
                continue
            merged = parts[0] if len(parts) == 1 else _concat(parts)
            if len(parts) > 1:
                merged = merged.take(np.argsort(merged.t, kind="stable"))
            ready.append(merged)
            size += len(merged)
            while size >= self.ctx.batch_size:
                batch, ready = _split(_concat(ready), self.ctx.batch_size)
                size -= len(batch)
                yield self._batch(batch)
        if ready:
            yield self._batch(_concat(ready))

    def _batch(self, rows: _Rows) -> FrameBatch:
        self.ctx.frames += len(rows)
        return FrameBatch(
            t=rows.t,
            can_id=rows.can_id,
            flags=rows.flags,
            dlc=rows.dlc,
            data=rows.data,
            channel=rows.channel,
            line=rows.line,
            channels=tuple(self.names),
            long_data=rows.long,
        )

    def _no_can(self) -> str:
        names = sorted({ch.name for g in self.mdf.groups for ch in g.channels})
        if not names:
            return "an MF4 file without channel groups: no CAN bus logging in it"
        shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")
        return (
            "an MF4 file without CAN bus logging (no CAN_DataFrame, CAN_RemoteFrame or "
            f"CAN_ErrorFrame records; its channels: {shown})"
        )


def _outside(channels, record: int) -> str:
    """The first channel whose bytes lie outside the group's record, described, or "".
    asammdf reads such a channel past its buffers (a corrupt byte offset was a segfault)."""
    for ch in channels:
        kind = int(ch.channel_type)
        if kind in (3, 6):  # virtual: no bytes in the record
            continue
        bits = 64 if kind == 1 else int(ch.bit_count)  # VLSD: an 8-byte offset in the record
        end = int(ch.byte_offset) + (int(ch.bit_offset) + bits + 7) // 8
        if end > record:
            return (
                f"channel {ch.name} ends at byte {end} of a {record}-byte record "
                f"(byte offset {ch.byte_offset}, {bits} bits)"
            )
    return ""


def _values(name: str, signal) -> np.ndarray:
    """A field's values: the raw ones, through the channel's numeric conversion where it
    has one. CANedge (firmware 01.07 on) writes BusChannel, IDE, Dir and EDL as virtual
    channels (no bytes in the record; the raw value is the record's index) whose linear
    conversion gives the constant of their group (CAN2_Rx: BusChannel 2, Dir 0), and
    DataLength as DLC's bits through a value table (DLC 9 -> 12 bytes). The ID and the
    data bytes stay raw; a value-to-text conversion is not applied (its numbers are kept)."""
    if name in ("ID", "DataBytes") or getattr(signal, "conversion", None) is None:
        return signal.samples
    return signal.physical(ignore_value2text_conversions=True).samples


def _split(rows: _Rows, n: int) -> tuple[_Rows, list[_Rows]]:
    head = rows.take(slice(0, n))
    rest = rows.take(slice(n, len(rows)))
    return head, [rest] if len(rest) else []


def _bytes(samples, n: int) -> np.ndarray:
    """DataBytes as an (n, width) uint8 array, whichever way asammdf gives them."""
    if samples is None:
        return np.zeros((n, 0), np.uint8)
    a = np.asarray(samples[:n])
    if a.dtype == np.uint8 and a.ndim == 2:
        return a
    if a.dtype.kind in "SV" and a.ndim == 1:  # fixed-size byte strings
        return np.frombuffer(a.tobytes(), np.uint8).reshape(n, a.dtype.itemsize)
    if a.ndim == 2:
        return a.astype(np.uint8)
    # variable length (VLSD): one bytes object each
    rows = [bytes(v) for v in a.tolist()]
    width = max((len(r) for r in rows), default=0)
    out = np.zeros((n, width), np.uint8)
    for i, r in enumerate(rows):
        out[i, : len(r)] = np.frombuffer(r, np.uint8)
    return out


def _say(exc: BaseException) -> str:
    """asammdf's reason in one line; a struct error is a block cut short."""
    if isinstance(exc, struct.error):
        return f"a block ends before its fields do, the file is cut off or corrupt ({exc})"
    text = str(exc).strip().splitlines()
    return text[0][:200] if text else exc.__class__.__name__


@contextmanager
def _quiet():
    """asammdf's warnings and log records kept off stderr while it reads: it logs what
    it finds wrong with a damaged file (with an empty traceback) to its own handler,
    and the reader reports the damage itself, once, as a problem."""
    log = logging.getLogger("asammdf")
    disabled, log.disabled = log.disabled, True
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        log.disabled = disabled


def _open(module, stream: BinaryIO):
    """(asammdf's MDF, "") or (None, why not). Without its bus-logging pass (which reads
    every group's BusChannel and ID at open, for DBC decoding: the file's size in memory).
    A half-built MDF4's __del__ fails when its constructor did: that is asammdf's
    tidying, not news, and is kept off stderr."""
    hook = sys.unraisablehook

    def quiet(unraisable) -> None:
        if getattr(unraisable.object, "__module__", "").startswith("asammdf"):
            return
        hook(unraisable)

    sys.unraisablehook = quiet
    try:
        why = ""
        try:
            with _quiet():
                return module.MDF(stream, process_bus_logging=False), ""
        except Exception as exc:  # MdfException, struct.error, ValueError, ... on damage
            why = _say(exc)
        return None, why
    finally:
        gc.collect()
        sys.unraisablehook = hook


@contextmanager
def _seekable(stream: BinaryIO, head: bytes):
    """The stream itself when asammdf may read it in place, else a temporary copy:
    a pipe or gzip stream cannot seek, and asammdf finalises an unfinalised file by
    writing into what it is given (never the log on disk)."""
    if stream.seekable() and head[:8] == MAGICS[0]:
        stream.seek(0)
        yield stream
        return
    with tempfile.TemporaryFile(prefix="cananalyze-mf4-") as tmp:
        shutil.copyfileobj(stream, tmp, 1 << 20)
        tmp.seek(0)
        yield tmp


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    """The CAN frames of an MF4 file's bus-logging groups, merged by time."""
    ctx.format = "mf4"
    mdf_module = need("asammdf", "reading MF4 logs", "mf4")
    head = stream.read(16)
    if not sniff(head):
        ctx.problems.add(ctx.source, "offset 0", "not an MDF file (no MDF identification)")
        return
    version = head[8:16].strip(b" \0").decode("ascii", "replace")
    if not version.startswith("4."):
        ctx.problems.add(
            ctx.source,
            "offset 8",
            f"MDF version {version}: bus logging (CAN_DataFrame) is MDF 4; not read",
        )
        return
    if stream.seekable():
        stream.seek(0)
        source: BinaryIO = stream
    else:
        source = io.BufferedReader(_Prefixed(head, stream))  # type: ignore[arg-type]
    with _seekable(source, head) as seekable:
        mdf, why = _open(mdf_module, seekable)
        if mdf is None:
            ctx.problems.add(ctx.source, "offset 0", f"not a readable MF4 file: {why}")
            return
        try:
            reader = _Reader(mdf, ctx)
            abs_ns = int(mdf.header.abs_time)
            if abs_ns:
                reader.start = abs_ns // 10**9 + (abs_ns % 10**9) / 1e9
                ctx.absolute_time = True
                ctx.start_time = reader.start
            yield from reader.batches()
        finally:
            mdf.close()


class _Prefixed(io.RawIOBase):
    """The bytes read to check the head, then the rest of an unseekable stream."""

    def __init__(self, head: bytes, rest: BinaryIO) -> None:
        self._head = memoryview(head)
        self._rest = rest

    def readable(self) -> bool:
        return True

    def readinto(self, buf) -> int:  # type: ignore[override]
        if self._head:
            n = min(len(buf), len(self._head))
            buf[:n] = self._head[:n]
            self._head = self._head[n:]
            return n
        data = self._rest.read(len(buf))
        buf[: len(data)] = data
        return len(data)


FORMAT = register(
    LogFormat(
        name="mf4",
        description="ASAM MDF4 bus logging (CANedge, Vector, Kvaser)",
        sniff=sniff,
        read=read,
        suffixes=(".mf4",),
        priority=13,
        text=False,
    )
)
