"""Vector BLF binary logs: CAN (FD) message and extended error records in LOG_CONTAINERs.

python-can's BLFReader unpacks one struct and builds one Message per frame. Here
each container is decompressed, a short loop walks the object headers only to
find where each record starts (records may straddle containers), and the fields
of all CAN records are then gathered with numpy fancy indexing at those offsets.
Layouts follow python-can's blf.py (itself from Toby Lorenz' vector_blf).

Containers are read one at a time; a container larger than MAX_CONTAINER, or one
that inflates beyond it, is refused with a problem (decompression bomb), and a
file cut inside a container yields the complete records and reports the rest.
"""

from __future__ import annotations

import datetime
import struct
import zlib
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from ..frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
    concat,
)
from .registry import LogFormat, ReadContext, register

MAX_CONTAINER = 64 << 20  # real containers are ~128 KiB uncompressed

_FILE_HEADER = struct.Struct("<4sLBBBBBBBBQQLL8H8H")
_OBJ_BASE = struct.Struct("<4sHHLL")  # signature, header size, header version, size, type
_CONTAINER = struct.Struct("<H6xL4x")  # compression method, uncompressed size

CAN_MESSAGE = 1
LOG_CONTAINER = 10
CAN_ERROR_EXT = 73
CAN_MESSAGE2 = 86
CAN_FD_MESSAGE = 100
CAN_FD_MESSAGE_64 = 101
_WANTED = (CAN_MESSAGE, CAN_MESSAGE2, CAN_ERROR_EXT, CAN_FD_MESSAGE, CAN_FD_MESSAGE_64)
# Bytes of each record body that must be present (payload starts after the object header).
_BODY = {
    CAN_MESSAGE: 16,
    CAN_MESSAGE2: 16,
    CAN_ERROR_EXT: 32,
    CAN_FD_MESSAGE: 84,
    CAN_FD_MESSAGE_64: 40,
}

_DLC2LEN = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64], np.uint8)


def sniff(head: bytes) -> bool:
    return head[:4] == b"LOGG"


def _systemtime(fields: tuple[int, ...]) -> float | None:
    """Epoch of a BLF SYSTEMTIME (UTC, millisecond resolution), None when unset."""
    year, month, _dow, day, hour, minute, sec, ms = fields
    try:
        dt = datetime.datetime(year, month, day, hour, minute, sec, ms * 1000, tzinfo=datetime.UTC)
    except ValueError:
        return None
    return dt.timestamp()


def _u(buf: np.ndarray, at: np.ndarray, width: int) -> np.ndarray:
    """Little-endian unsigned ints of ``width`` bytes at byte offsets ``at``."""
    dtype = {1: "<u1", 2: "<u2", 4: "<u4", 8: "<u8"}[width]
    idx = at[:, None] + np.arange(width)
    return np.ascontiguousarray(buf[idx]).view(dtype)[:, 0]


def _bytes8(buf: np.ndarray, at: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(n, 8) data slots from offsets ``at``, bytes beyond ``count`` zeroed."""
    idx = at[:, None] + np.arange(8)
    idx = np.minimum(idx, len(buf) - 1)
    out = buf[idx].copy()
    out[np.arange(8)[None, :] >= count[:, None]] = 0
    return out


class _Records:
    """Decoded-but-unparsed record bytes carried from container to container."""

    def __init__(self, ctx: ReadContext, start: float) -> None:
        self.ctx = ctx
        self.start = start
        self.tail = b""
        self.record = 0  # 1-based number of the last object seen inside containers
        self.channels: list[str] = []
        self._chan: dict[int, int] = {}

    def parse(self, data: bytes) -> FrameBatch | None:
        buf = self.tail + data if self.tail else data
        end = len(buf)
        pos = 0
        runs: list[tuple] = []  # (offsets, kinds, record numbers, sizes), in file order
        offs: list[int] = []
        kinds: list[int] = []
        nums: list[int] = []
        sizes: list[int] = []
        unpack = _OBJ_BASE.unpack_from
        while pos + 16 <= end:
            if buf[pos : pos + 4] != b"LOBJ":
                nxt = buf.find(b"LOBJ", pos, pos + 8)  # objects are padded to 4 bytes
                if nxt < 0:
                    nxt = buf.find(b"LOBJ", pos)
                    self.ctx.problems.add(
                        self.ctx.source,
                        f"record {self.record + 1}",
                        f"garbage between BLF objects, skipped {(nxt if nxt >= 0 else end) - pos} bytes",
                    )
                    if nxt < 0:
                        pos = end
                        break
                pos = nxt
                if pos + 16 > end:
                    break
            _, hsize, hver, size, kind = unpack(buf, pos)
            if size < 16 or size > MAX_CONTAINER:
                self.record += 1
                self.ctx.problems.add(
                    self.ctx.source, f"record {self.record}", f"BLF object with bad size {size}"
                )
                pos += 4
                continue
            if pos + size > end:
                break  # continues in the next container
            self.record += 1
            if kind in _WANTED:
                if hver not in (1, 2) or size < hsize + _BODY[kind]:
                    self.ctx.problems.add(
                        self.ctx.source,
                        f"record {self.record}",
                        f"BLF object type {kind} with header v{hver} size {size} unreadable",
                    )
                else:
                    offs.append(pos)
                    kinds.append(kind)
                    nums.append(self.record)
                    sizes.append(size)
                    run = self._uniform_run(buf, pos + size, end, buf[pos : pos + 16])
                    if run:
                        if offs:
                            runs.append((offs, kinds, nums, sizes))
                            offs, kinds, nums, sizes = [], [], [], []
                        at = pos + size * np.arange(1, run + 1, dtype=np.int64)
                        rec = self.record + np.arange(1, run + 1, dtype=np.int64)
                        runs.append((at, np.full(run, kind), rec, np.full(run, size)))
                        self.record += run
                        pos += size * run
            pos += size
        self.tail = buf[pos:]
        if offs:
            runs.append((offs, kinds, nums, sizes))
        if not runs:
            return None
        cols = [np.concatenate([np.asarray(r[k], np.int64) for r in runs]) for k in range(4)]
        return self._columns(np.frombuffer(buf, np.uint8), *cols)

    @staticmethod
    def _uniform_run(buf: bytes, pos: int, end: int, header: bytes) -> int:
        """How many objects from `pos` on have exactly this 16-byte object header.

        Loggers write long runs of one record type and size (CAN_MESSAGE: 48
        bytes); such a run is checked in one numpy pass instead of walked.
        """
        size = int.from_bytes(header[8:12], "little")
        count = (end - pos) // size
        if count < 4:
            return 0
        rows = np.frombuffer(buf, np.uint8, count * size, pos).reshape(count, size)[:, :16]
        same = np.all(rows == np.frombuffer(header, np.uint8), axis=1)
        bad = np.flatnonzero(~same)
        return int(bad[0]) if bad.size else count

    def _columns(self, buf, offs, kinds, nums, sizes) -> FrameBatch:
        o = np.array(offs, np.int64)
        kind = np.array(kinds, np.int64)
        size = np.array(sizes, np.int64)
        n = len(o)
        hsize = _u(buf, o + 4, 2).astype(np.int64)
        tflags = _u(buf, o + 16, 4)
        stamp = _u(buf, o + 24, 8).astype(np.float64)
        t = np.where(tflags == 1, stamp * 1e-5, stamp * 1e-9) + self.start
        p = o + hsize  # record body
        b = FrameBatch.allocate(n)
        b.t = t
        b.line = np.array(nums, np.int64)
        chan = np.zeros(n, np.int64)

        m = (kind == CAN_MESSAGE) | (kind == CAN_MESSAGE2)
        if m.any():
            q = p[m]
            chan[m] = _u(buf, q, 2)
            fl = _u(buf, q + 2, 1)
            dlc = np.minimum(_u(buf, q + 3, 1), 8)
            raw = _u(buf, q + 4, 4)
            b.can_id[m] = raw & 0x1FFFFFFF
            b.flags[m] = (
                np.where(raw & 0x80000000, FLAG_EXT, 0)
                | np.where(fl & 0x80, FLAG_RTR, 0)
                | np.where(fl & 0x01, FLAG_TX, 0)
            )
            b.dlc[m] = dlc
            b.data[m] = _bytes8(buf, q + 8, np.where(fl & 0x80, 0, dlc))

        m = kind == CAN_ERROR_EXT
        if m.any():
            q = p[m]
            chan[m] = _u(buf, q, 2)
            dlc = np.minimum(_u(buf, q + 11, 1), 8)
            raw = _u(buf, q + 16, 4)
            b.can_id[m] = raw & 0x1FFFFFFF
            b.flags[m] = FLAG_ERR | np.where(raw & 0x80000000, FLAG_EXT, 0)
            b.dlc[m] = dlc
            b.data[m] = _bytes8(buf, q + 24, dlc)

        m = kind == CAN_FD_MESSAGE
        if m.any():
            q = p[m]
            chan[m] = _u(buf, q, 2)
            fl = _u(buf, q + 2, 1)
            code = _u(buf, q + 3, 1) & 0x0F
            raw = _u(buf, q + 4, 4)
            fd = _u(buf, q + 13, 1)
            valid = np.minimum(_u(buf, q + 14, 1), 64)
            rtr = (fl & 0x80) != 0
            b.can_id[m] = raw & 0x1FFFFFFF
            b.flags[m] = (
                np.where(raw & 0x80000000, FLAG_EXT, 0)
                | np.where(rtr, FLAG_RTR, 0)
                | np.where(fl & 0x01, FLAG_TX, 0)
                | np.where(fd & 0x1, FLAG_FD, 0)
                | np.where(fd & 0x2, FLAG_BRS, 0)
                | np.where(fd & 0x4, FLAG_ESI, 0)
            )
            b.dlc[m] = np.where(rtr & (valid == 0), _DLC2LEN[code], valid)
            b.data[m] = _bytes8(buf, q + 20, valid)
            self._long(b, buf, np.flatnonzero(m), q + 20, valid, valid)

        m = kind == CAN_FD_MESSAGE_64
        if m.any():
            q = p[m]
            chan[m] = _u(buf, q, 1)
            code = _u(buf, q + 1, 1) & 0x0F
            valid = np.minimum(_u(buf, q + 2, 1), 64).astype(np.int64)
            raw = _u(buf, q + 4, 4)
            fd = _u(buf, q + 12, 4)
            direction = _u(buf, q + 34, 1)
            ext_off = _u(buf, q + 35, 1).astype(np.int64)
            # python-can issue 1905: valid_bytes may exceed the bytes stored; pad with zeros
            room = np.where(ext_off > 0, ext_off, size[m]) - hsize[m] - 40
            stored = np.clip(np.minimum(valid, room), 0, 64)
            rtr = (fd & 0x0010) != 0
            b.can_id[m] = raw & 0x1FFFFFFF
            b.flags[m] = (
                np.where(raw & 0x80000000, FLAG_EXT, 0)
                | np.where(rtr, FLAG_RTR, 0)
                | np.where(direction != 0, FLAG_TX, 0)
                | np.where(fd & 0x1000, FLAG_FD, 0)
                | np.where(fd & 0x2000, FLAG_BRS, 0)
                | np.where(fd & 0x4000, FLAG_ESI, 0)
            )
            b.dlc[m] = np.where(rtr & (valid == 0), _DLC2LEN[code], valid)
            b.data[m] = _bytes8(buf, q + 40, np.minimum(stored, 8))
            self._long(b, buf, np.flatnonzero(m), q + 40, stored, valid)

        b.channel = self._channel_index(chan)
        b.channels = tuple(self.channels)
        self.ctx.frames += n
        return b

    @staticmethod
    def _long(b, buf, rows, at, stored, valid) -> None:
        """CAN FD payloads over 8 bytes go to long_data (rare, so per row is fine)."""
        for r, a, s, v in zip(rows, at, stored, valid, strict=True):
            if v > 8:
                b.long_data[int(r)] = buf[a : a + s].tobytes().ljust(int(v), b"\0")

    def _channel_index(self, chan: np.ndarray) -> np.ndarray:
        """Map BLF channel numbers (1-based, as Vector shows them) to stable indices."""
        out = np.zeros(len(chan), np.uint16)
        for c in np.unique(chan).tolist():
            idx = self._chan.get(c)
            if idx is None:
                idx = self._chan[c] = len(self.channels)
                self.channels.append(str(c))
            out[chan == c] = idx
        return out


def _inflate(payload: bytes, limit: int) -> tuple[bytes, str | None]:
    """zlib-inflate at most ``limit`` bytes; the error text if it is broken or too big."""
    z = zlib.decompressobj()
    try:
        out = z.decompress(payload, limit)
    except zlib.error as e:
        return b"", f"corrupt zlib data ({e})"
    if z.unconsumed_tail:
        return out, f"container inflates beyond {limit} bytes (refused)"
    if not z.eof:
        return out, "compressed container is incomplete"
    return out, None


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "blf"
    head = stream.read(_FILE_HEADER.size)
    if len(head) < _FILE_HEADER.size or head[:4] != b"LOGG":
        ctx.problems.add(ctx.source, "offset 0", "not a BLF file (no LOGG header)")
        return
    fields = _FILE_HEADER.unpack(head)
    start = _systemtime(fields[14:22])
    if start is not None:
        ctx.absolute_time = True
        ctx.start_time = start
    rest = max(0, fields[1] - _FILE_HEADER.size)
    if len(stream.read(rest)) < rest:
        ctx.problems.add(ctx.source, f"offset {_FILE_HEADER.size}", "file ends inside the BLF file header")
        return
    offset = max(fields[1], _FILE_HEADER.size)
    declared_size = fields[10]  # 0 when the logger never closed the file
    records = _Records(ctx, start or 0.0)
    pending: list[FrameBatch] = []
    pending_rows = 0
    while True:
        base = stream.read(16)
        if not base:
            if declared_size > offset:  # ends cleanly between objects, but short of its own header's size
                ctx.problems.add(
                    ctx.source,
                    f"offset {offset}",
                    f"file ends here but its header says {declared_size} bytes (cut short?)",
                )
            break
        where = f"offset {offset}"
        if len(base) < 16:
            ctx.problems.add(
                ctx.source, where, f"file ends inside an object header ({len(base)} bytes)"
            )
            break
        sig, _, _, size, kind = _OBJ_BASE.unpack(base)
        if sig != b"LOBJ":
            ctx.problems.add(
                ctx.source, where, "expected a BLF object (LOBJ), file is corrupt here"
            )
            break
        if size < 16 or size > MAX_CONTAINER:
            ctx.problems.add(ctx.source, where, f"BLF object size {size} is absurd (refused)")
            break
        body = stream.read(size - 16)
        stream.read(size % 4)  # padding
        offset += size + size % 4
        truncated = len(body) < size - 16
        if kind != LOG_CONTAINER:
            if truncated:
                ctx.problems.add(ctx.source, where, "file ends inside an object")
                break
            continue
        if len(body) < _CONTAINER.size:
            ctx.problems.add(ctx.source, where, "file ends inside a container header")
            break
        method, _usize = _CONTAINER.unpack_from(body)
        payload = body[_CONTAINER.size :]
        if method == 0:
            data, err = payload, None
        elif method == 2:
            data, err = _inflate(payload, MAX_CONTAINER)
        else:
            ctx.problems.add(ctx.source, where, f"unknown container compression {method}, skipped")
            continue
        if truncated:
            err = f"file ends inside a container ({len(body) + 16} of {size} bytes)"
        batch = records.parse(data)
        if err:
            ctx.problems.add(ctx.source, where, err)
        if batch is not None:
            pending.append(batch)
            pending_rows += len(batch)
        while pending_rows >= ctx.batch_size:
            joined = concat(pending)
            out = joined.take(slice(0, ctx.batch_size))
            rest = joined.take(slice(ctx.batch_size, None))
            yield out
            pending = [rest] if len(rest) else []
            pending_rows = len(rest)
        if truncated or (err and method == 2 and "incomplete" in err):
            break
    if records.tail:
        ctx.problems.add(
            ctx.source,
            f"record {records.record + 1}",
            f"incomplete BLF object at end of data ({len(records.tail)} bytes) skipped",
        )
    if pending_rows:
        yield concat(pending)


FORMAT = register(
    LogFormat(
        name="blf",
        description="Vector BLF binary log",
        sniff=sniff,
        read=read,
        suffixes=(".blf",),
        priority=10,
    )
)
