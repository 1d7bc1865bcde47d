"""Vector BLF binary logs: CAN (FD) message and extended error records in LOG_CONTAINERs.

python-can's BLFReader unpacks one struct and builds one Message per frame. Here
containers are decompressed (the system's libdeflate straight into one reused
buffer when it is there, else python-isal or zlib) and about 2 MiB of their bytes
walked at once (records may straddle containers). With the compiled helper, its
`blf_records` walks the objects and writes every CAN record straight into the
frame columns, without the GIL (`_parse_c`). Without it (`_parse_py`), a short
loop walks the object headers only to find where each record starts, and the
fields of all CAN records are then read with numpy: through one strided view
when the records are evenly spaced (a run of one type and size, the usual case),
else by fancy indexing at those offsets. Both walks give the same rows and
problems (tests/test_speedups_blf.py).
Layouts follow python-can's blf.py (itself from Toby Lorenz' vector_blf).

Containers are read one at a time; a container larger than MAX_CONTAINER, or one
that inflates beyond it, is refused with a problem (decompression bomb), and a
file cut inside a container yields the complete records and reports the rest.

Damage never becomes a frame (docs/hostile-input.md): objects are believed only
when their header, their time and the object after them say they are sound
(`_Records`), a broken zlib container gives what it inflated to before the damage
(`_salvage`, `_Inflated.trim`), and the walk resynchronises on the next `LOBJ`,
also inside a plain container whose header was lost; each run of skipped bytes
is one problem naming its offset.
"""

from __future__ import annotations

import bisect
import ctypes
import ctypes.util
import datetime
import math
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np

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
from cananalyze.formats.logs._pycan_writer import PycanWriter
from cananalyze.formats.registry import LogFormat, ReadContext, register
from cananalyze.runtime import speedups

try:  # python-isal: the same inflate as zlib, ~1.6x faster and outside the GIL
    from isal import isal_zlib as _fast_zlib
except ImportError:  # not installed (no wheel for this machine): the standard library's
    _fast_zlib = None

MAX_CONTAINER = 64 << 20  # real containers are ~128 KiB uncompressed
MAX_FILE_HEADER = 1 << 16  # real file headers are 144 bytes
MAX_INNER = 1 << 20  # an object inside a container (CAN records are < 200 bytes)
# What an object inside a container must look like to be believed (see _Records):
MAX_OBJECT_TYPE = 255  # object types known run to 133 (vector_blf, Wireshark, 2024)
MAX_OBJ_HEADER = 64  # object header sizes are 32 (header v1) and 40 (v2)
MAX_CAN_OBJECT = 512  # a CAN or CAN FD record object; real ones are at most 144 bytes
TIME_SLACK = 86400.0  # s an object's time may lie before the file's start or after its stop
MAX_SPAN = 366 * 86400.0  # s of times believed when the file header gives no stop time
# In the data of a container whose zlib stream is broken, the first record more than
# this before or after the record before it ends what is believed (`_Inflated.trim`)
DAMAGED_BACK = 1.0  # s
DAMAGED_GAP = 60.0  # s
PARSE_BYTES = 2 << 20  # decompressed bytes parsed in one go (see _Inflated)
# deflate's largest expansion: a 258-byte match in 2 bits is 1032 bytes per input byte
_DEFLATE_RATIO = 1040

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
_OBJ_HEADER = 32  # the shortest object header (base and v1): its flags and time end there
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


# _KEEP8[k] keeps the first k bytes of a little-endian uint64 (an 8-byte data slot)
_KEEP8 = np.array([(1 << (8 * k)) - 1 for k in range(9)], np.uint64)
_WIDTH = {1: "<u1", 2: "<u2", 4: "<u4", 8: "<u8"}


class _At:
    """Byte offsets of records in ``buf``: any offsets, or an evenly spaced run.

    An evenly spaced run (every record of one type and size, the usual case) is
    read through a strided view with no index arrays; other offsets are
    gathered with fancy indexing.
    """

    def __init__(self, buf: np.ndarray, base: np.ndarray, stride: int = 0, shift: int = 0) -> None:
        self.buf = buf
        self.base = base
        self.stride = stride
        self.shift = shift

    @property
    def at(self) -> np.ndarray:
        return self.base + self.shift

    def __add__(self, k: int) -> _At:
        return _At(self.buf, self.base, self.stride, self.shift + k)

    def __getitem__(self, sel) -> _At:
        if isinstance(sel, slice):
            return self
        return _At(self.buf, self.base[sel], 0, self.shift)

    def _view(self, width: int, cols: int) -> np.ndarray | None:
        n = len(self.base)
        if not self.stride or not n:
            return None
        first = int(self.base[0]) + self.shift
        if first + (n - 1) * self.stride + width * cols > len(self.buf):
            return None
        shape, strides = ((n,), (self.stride,)) if cols == 1 else ((n, cols), (self.stride, 1))
        dtype = _WIDTH[width] if cols == 1 else np.uint8
        return np.ndarray(shape, dtype, buffer=self.buf, offset=first, strides=strides)

    def u(self, width: int) -> np.ndarray:
        """Little-endian unsigned ints of ``width`` bytes at these offsets."""
        view = self._view(width, 1)
        if view is not None:
            return view.copy()
        idx = self.at[:, None] + np.arange(width)
        return np.ascontiguousarray(self.buf[idx]).view(_WIDTH[width])[:, 0]

    def bytes8(self, count: np.ndarray) -> np.ndarray:
        """(n, 8) data slots from these offsets, bytes beyond ``count`` zeroed."""
        out = self._view(1, 8)
        if out is not None:
            out = out.copy()
        else:
            idx = np.minimum(self.at[:, None] + np.arange(8), len(self.buf) - 1)
            out = self.buf[idx]
        out.view("<u8")[:, 0] &= _KEEP8[np.minimum(count, 8)]
        return out


# Why the walk skipped bytes, by the code the compiled walk reports it with: the first
# reason of a run of skipped bytes (a, b, c: its numbers) goes into the run's problem.
_GARBAGE, _BAD_SIZE, _BAD_TYPE, _BAD_HEADER, _BAD_RECORD, _BAD_TIME, _NO_NEXT, _CUT = range(1, 9)
_OUT_OF_STEP, _OUT_OF_SHAPE = 9, 10  # only in a broken container's data (`_Inflated.trim`)
_REASONS = {
    _GARBAGE: "bytes that are no BLF object",
    _BAD_SIZE: "an object size of {0} bytes",
    _BAD_TYPE: "object type {0}",
    _BAD_HEADER: "a type {0} object with a v{1} header of {2} bytes",
    _BAD_RECORD: "a type {0} record of {1} bytes",
    _BAD_TIME: "a type {0} record at {1} s, outside the file's times",
    _NO_NEXT: "a type {0} object not followed by another",
    _CUT: "an object cut short by the end of the data",
    _OUT_OF_STEP: "a type {0} record at {1} s, {2} ms from the one before",
    _OUT_OF_SHAPE: "a type {0} record whose fields are no CAN frame's",
}
_RUN_GAP = 16  # skipped bytes this close together (no object between them): one run
MAX_WALK_PROBLEMS = 64  # runs of skipped bytes one compiled walk keeps; more: the Python walk


class _Columns:
    """Column buffers the compiled walk fills, kept from buffer to buffer (rows: capacity)."""

    def __init__(self, rows: int) -> None:
        self.rows = rows
        self.t = np.empty(rows, np.float64)
        self.can_id = np.empty(rows, np.uint32)
        self.flags = np.empty(rows, np.uint8)
        self.dlc = np.empty(rows, np.uint8)
        self.data = np.empty((rows, 8), np.uint8)
        self.chan = np.empty(rows, np.uint16)
        self.line = np.empty(rows, np.int64)
        self.long = np.empty((rows * 2 // 3 + 1, 4), np.int64)  # each at least 72 bytes
        self.probs = np.empty((MAX_WALK_PROBLEMS, 6), np.int64)

    def buffers(self) -> tuple[np.ndarray, ...]:
        return (
            self.t,
            self.can_id,
            self.flags,
            self.dlc,
            self.data,
            self.chan,
            self.line,
            self.long,
            self.probs,
        )


def _sel(m: np.ndarray) -> np.ndarray | slice:
    """The mask itself, or a plain slice when it selects every row (no gather/scatter)."""
    return slice(None) if m.all() else m


def _judge(hsize: int, hver: int, size: int, kind: int) -> tuple | None:
    """Why an object header inside a container is not believed (a reason and its
    numbers), or None (the compiled walk judges the same)."""
    if size < 16 or size > MAX_INNER:  # a claimed 60 MiB swallowed the containers after it
        return (_BAD_SIZE, size, 0, 0)
    if kind == 0 or kind > MAX_OBJECT_TYPE or kind == LOG_CONTAINER:
        return (_BAD_TYPE, kind, 0, 0)
    if kind in _WANTED:
        if hver not in (1, 2) or hsize < _OBJ_HEADER or hsize > MAX_OBJ_HEADER:
            return (_BAD_HEADER, kind, hver, hsize)
        if size < hsize + _BODY[kind] or size > MAX_CAN_OBJECT:
            return (_BAD_RECORD, kind, size, 0)
    elif hsize < 16 or hsize > MAX_OBJ_HEADER or hsize > size:
        return (_BAD_HEADER, kind, hver, hsize)
    return None


def _frame_shaped(buf: bytes, body: int, kind: int) -> bool:
    """Whether the fields of a CAN record (its body at ``body``) hold only values a CAN
    frame can have: message flags of the known bits (Tx, NERR, wake-up, remote), a DLC
    code under 16, at most 64 valid data bytes. Only asked of a broken container's data
    (`_Inflated.trim`): a sound log is read as it is."""
    if kind == CAN_FD_MESSAGE_64:
        return buf[body + 1] < 16 and buf[body + 2] <= 64
    if kind == CAN_ERROR_EXT:
        return buf[body + 10] < 16  # its DLC (python-can reads it there too)
    if buf[body + 2] & 0x1E or buf[body + 3] >= 16:
        return False
    return kind != CAN_FD_MESSAGE or buf[body + 14] <= 64


def _merge(skips: list) -> list:
    """Skipped byte ranges (start, end, reason, a, b, c), sorted, as runs: ranges with
    no object between them (less than _RUN_GAP bytes apart) are one run, with the
    first range's reason (the compiled walk merges them the same way as it goes)."""
    runs: list[list] = []
    for start, end, *why in skips:
        if runs and start - runs[-1][1] < _RUN_GAP:
            runs[-1][1] = end
        else:
            runs.append([start, end, *why])
    return runs


class _Records:
    """The record walk over inflated bytes; its record count, channel table, time range
    and an unfinished run of skipped bytes carry from buffer to buffer.

    Damaged container data (a broken zlib stream inflates to garbage before its error
    shows; zeroed or overwritten bytes) must not become frames. An object is believed
    only when its header is sound (size, type, header version and size, a CAN record's
    size for its type), it is followed by the next object's signature (or the end of
    the data), and a CAN record's time lies in the file's range: from TIME_SLACK before
    the file header's start to TIME_SLACK after its stop (MAX_SPAN when it has no stop;
    without a start, MAX_SPAN around the first record's time). Anything else is
    skipped up to the next signature `LOBJ`; each run of skipped bytes is one problem
    naming the container (its file offset), the byte in its data and how many bytes.
    """

    def __init__(self, ctx: ReadContext, start: float, lo: float, hi: float) -> None:
        self.ctx = ctx
        self.start = start
        self.lo, self.hi = lo, hi  # believed record times, s from `start`; nan: not known yet
        self.record = 0  # 1-based number of the last object seen inside containers
        self.channels: list[str] = []
        self._chan: dict[str, int] = {}
        self._out: _Columns | None = None  # the compiled walk's buffers, reused
        # a run of skipped bytes that reached the end of the last walk:
        # [location, bytes, reason, a, b, c], and the bytes walked after it
        self._open: list | None = None
        self._open_gap = 0

    def parse(self, buf, batches: _Cutter, final: bool, where) -> int:
        """The records of ``buf`` (the previous tail, then inflated container bytes)
        into ``batches``; returns how many bytes were walked (the rest is the new tail:
        a record that continues in the next container). ``final``: no more bytes follow
        these (the end of the data, or a gap in it): nothing is left as a tail.
        ``where(pos)``: the container offset and byte in its data of buffer byte pos."""
        walk = getattr(speedups.C, "blf_records", None)
        done = None
        if walk is not None:
            done = self._parse_c(walk, buf, batches, final)
        if done is None:
            got, pos, runs = self._parse_py(bytes(buf), final)
            if got is not None:
                batches.add(got)
        else:
            pos, runs = done
        self._report(runs, pos, final, where)
        return pos

    def _parse_c(self, walk, buf, batches: _Cutter, final: bool):
        """The compiled walk (_speedups.blf_records): the same rows and runs of skipped
        bytes as `_parse_py`, written straight into the batch being filled when they
        fit in it, else into reused buffers and copied; (bytes walked, runs), or None
        when it declines the buffer (more runs in it than it keeps: hostile input,
        which the Python walk takes)."""
        cap = len(buf) // 48  # the most rows it can hold (each at least 48 bytes)
        if self._out is None or self._out.rows < cap:
            self._out = _Columns(max(cap, 1 << 16))
        out = self._out
        spot = batches.room(cap)
        if spot is None:
            cols = out.buffers()
        else:
            b, at = spot
            cols = (b.t[at:], b.can_id[at:], b.flags[at:], b.dlc[at:], b.data[at:])
            cols += (b.channel[at:], b.line[at:], out.long, out.probs)
        limits = (MAX_INNER, MAX_OBJECT_TYPE, MAX_OBJ_HEADER, MAX_CAN_OBJECT)
        ok, n, pos, record, n_long, n_runs, lo, hi = walk(
            buf, self.record, limits, self.start, self.lo, self.hi, MAX_SPAN, final, *cols
        )
        if not ok:
            return None
        runs = out.probs[:n_runs].tolist()
        self.record = record
        self.lo, self.hi = lo, hi
        if not n:
            return pos, runs
        chan = cols[5][:n]
        chan[:] = self._channel_index(chan)
        long = {
            row: bytes(buf[a : a + s]).ljust(v, b"\0")
            for row, a, s, v in out.long[:n_long].tolist()
        }
        self.ctx.frames += n
        if spot is not None:
            batches.commit(n, tuple(self.channels), long)
        else:
            batches.add(
                FrameBatch(
                    t=out.t[:n],
                    can_id=out.can_id[:n],
                    flags=out.flags[:n],
                    dlc=out.dlc[:n],
                    data=out.data[:n],
                    channel=chan,
                    line=out.line[:n],
                    channels=tuple(self.channels),
                    long_data=long,
                )
            )
        return pos, runs

    def _report(self, runs: list, pos: int, final: bool, where) -> None:
        """One problem per run of skipped bytes, (start, end, reason, a, b, c) in the
        buffer just walked (`pos` bytes of it); a run that reaches the end of the walk
        stays open, to go on in the next one (unless ``final``)."""
        if self._open is not None and not runs:
            self._open_gap += pos
        for start, end, *why in runs:
            if self._open is not None and self._open_gap + start < _RUN_GAP:
                self._open[1] += self._open_gap + end  # the run carried from the last walk
            else:
                if self._open is not None:
                    self._close()
                self._open = [where(start), end - start, *why]
            self._open_gap = pos - end
        if self._open is not None and (final or self._open_gap >= _RUN_GAP):
            self._close()

    def _close(self) -> None:
        (offset, byte), skipped, reason, a, b, c = self._open  # type: ignore[misc]
        self._open = None
        self.ctx.problems.add(
            self.ctx.source,
            f"offset {offset}",
            f"damaged BLF data from byte {byte} of this container's data: skipped "
            f"{skipped} bytes to the next sound object (first: {_REASONS[reason].format(a, b, c)})",
        )

    def report_cut(self, where: tuple[int, int], skipped: int, reason: int, a, b, c) -> None:
        """The problem for what `_Inflated.trim` cut from a broken container's data."""
        offset, byte = where
        self.ctx.problems.add(
            self.ctx.source,
            f"offset {offset}",
            f"broken zlib data from byte {byte} of this container's data on: skipped "
            f"{skipped} bytes, the rest of it (first: {_REASONS[reason].format(a, b, c)})",
        )

    def _parse_py(self, buf: bytes, final: bool) -> tuple[FrameBatch | None, int, list]:
        """The Python walk: the rows of ``buf`` (None when none), the bytes walked and
        the runs of skipped bytes."""
        end = len(buf)
        lim = end if final else end - 16  # an object is taken when its successor is seen
        pos = 0
        runs: list[tuple] = []  # (offsets, kinds, record numbers, sizes), in file order
        offs: list[int] = []
        kinds: list[int] = []
        nums: list[int] = []
        sizes: list[int] = []
        skips: list[tuple] = []  # (start, end, reason, a, b, c) in walk order
        nonext: dict[int, tuple] = {}  # CAN records followed by garbage, by their offset
        prev = (-1, -1, 0, False)  # the last object taken: start, end, kind, a CAN record

        def garbage_after(at: int) -> None:
            """Bytes that are no object start at ``at``: the object taken just before them
            is not believed either (the damage may have begun inside it)."""
            if at == prev[1]:
                event = (prev[0], prev[1], _NO_NEXT, prev[2], 0, 0)
                if prev[3]:
                    nonext[prev[0]] = event  # its row is dropped in `_believed`
                else:
                    skips.append(event)

        unpack = _OBJ_BASE.unpack_from
        while pos + 16 <= end:
            if buf[pos : pos + 4] != b"LOBJ":
                nxt = buf.find(b"LOBJ", pos, pos + 8)  # objects are padded to 4 bytes
                if nxt < 0:
                    garbage_after(pos)
                    nxt = buf.find(b"LOBJ", pos)
                    stop = nxt if nxt >= 0 else (end if final else end - 3)
                    skips.append((pos, stop, _GARBAGE, 0, 0, 0))
                    if nxt < 0:
                        pos = stop
                        break
                pos = nxt
                if pos + 16 > end:
                    break
            _, hsize, hver, size, kind = unpack(buf, pos)
            bad = _judge(hsize, hver, size, kind)
            if bad is not None:
                self.record += 1
                skips.append((pos, pos + 4, *bad))
                pos += 4
                continue
            if pos + size > lim:
                if final:  # continues beyond the data
                    self.record += 1
                    skips.append((pos, end, _CUT, 0, 0, 0))
                    pos = end
                break  # continues in the next container
            self.record += 1
            if kind in _WANTED:
                offs.append(pos)
                kinds.append(kind)
                nums.append(self.record)
                sizes.append(size)
                run = self._uniform_run(buf, pos + size, lim, buf[pos : pos + 16])
                if run:
                    if offs:
                        runs.append((offs, kinds, nums, sizes))
                        offs, kinds, nums, sizes = [], [], [], []
                    at = pos + size * np.arange(1, run + 1, dtype=np.int64)
                    rec = self.record + np.arange(1, run + 1, dtype=np.int64)
                    runs.append((at, np.full(run, kind), rec, np.full(run, size)))
                    self.record += run
                    pos += size * run
            prev = (pos, pos + size, kind, kind in _WANTED)
            pos += size
        if final and pos < end:  # less than an object header is left (under 4 bytes: padding)
            if end - pos >= 4 and buf.find(b"LOBJ", pos, pos + 8) >= 0:
                skips.append((pos, end, _CUT, 0, 0, 0))
            elif end - pos >= 4:
                garbage_after(pos)
                skips.append((pos, end, _GARBAGE, 0, 0, 0))
            pos = end
        if offs:
            runs.append((offs, kinds, nums, sizes))
        batch = None
        if runs:
            cols = [np.concatenate([np.asarray(r[k], np.int64) for r in runs]) for k in range(4)]
            batch = self._believed(np.frombuffer(buf, np.uint8), cols, skips, nonext)
        skips.sort()
        return batch, pos, _merge(skips)

    def _believed(self, buf: np.ndarray, cols: list, skips: list, nonext: dict):
        """The rows of the CAN records whose time lies in the file's range and that are
        followed by another object (`nonext`: those that are not); the others become
        skipped bytes. None when no row is left."""
        o, kind, nums, size = cols
        step = int(size[0])
        even = bool((size == step).all() and (np.diff(o) == step).all())
        obj = _At(buf, o, step if even else 0)
        # the times in place, in as few arrays as can be (each is a fresh one per walk)
        rel = (obj + 24).u(8).view(np.int64).astype(np.float64)
        tens = (obj + 16).u(4) == 1  # 10 us ticks, else ns
        if not tens.any():
            rel *= 1e-9
        elif tens.all():
            rel *= 1e-5
        else:
            rel[tens] *= 1e-5
            rel[~tens] *= 1e-9
        if self.lo != self.lo:  # nan: no file times, a range around the first record's
            self.lo, self.hi = float(rel[0]) - MAX_SPAN, float(rel[0]) + MAX_SPAN
        good = rel >= self.lo
        good &= rel <= self.hi
        if nonext or not good.all():
            for i in np.flatnonzero(~good).tolist():
                end = int(o[i] + size[i])
                skips.append((int(o[i]), end, _BAD_TIME, int(kind[i]), int(rel[i]), 0))
            for at, event in nonext.items():
                i = int(np.searchsorted(o, at))
                if good[i]:
                    good[i] = False
                    skips.append(event)
            keep = np.flatnonzero(good)
            if not len(keep):
                return None
            o, kind, nums, size, rel = o[keep], kind[keep], nums[keep], size[keep], rel[keep]
            step = int(size[0])
            even = bool((size == step).all() and (np.diff(o) == step).all())
        return self._columns(buf, o, kind, nums, size, rel, step if even else 0)

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
        # the 16 header bytes of each object as two uint64 columns, compared in place
        rows = np.ndarray((count, 2), "<u8", buffer=buf, offset=pos, strides=(size, 8))
        h = np.frombuffer(header, "<u8")
        same = (rows[:, 0] == h[0]) & (rows[:, 1] == h[1])
        bad = np.flatnonzero(~same)
        return int(bad[0]) if bad.size else count

    def _columns(self, buf, o, kind, nums, size, rel, step: int) -> FrameBatch:
        """The rows of the records at offsets `o` (`rel`: their times from the start;
        `step`: their spacing when evenly spaced, else 0)."""
        n = len(o)
        obj = _At(buf, o, step)
        hsize = (obj + 4).u(2).astype(np.int64)
        h0 = int(hsize[0])
        same_h = step and bool((hsize == h0).all())
        p = _At(buf, o + hsize, step if same_h else 0)  # record bodies
        b = FrameBatch.allocate(n)
        rel += self.start  # in place: the walk's own array
        b.t = rel
        b.line = np.array(nums, np.int64)
        chan = np.zeros(n, np.int64)

        m = (kind == CAN_MESSAGE) | (kind == CAN_MESSAGE2)
        if m.any():
            m = _sel(m)
            q = p[m]
            chan[m] = q.u(2)
            fl = (q + 2).u(1)
            dlc = np.minimum((q + 3).u(1), 8)
            raw = (q + 4).u(4)
            b.can_id[m] = raw & 0x1FFFFFFF
            b.flags[m] = (
                np.where(raw & 0x80000000, FLAG_EXT, 0)
                | np.where(fl & 0x80, FLAG_RTR, 0)
                | np.where(fl & 0x01, FLAG_TX, 0)
            )
            b.dlc[m] = dlc
            b.data[m] = (q + 8).bytes8(np.where(fl & 0x80, 0, dlc))

        m = kind == CAN_ERROR_EXT
        if m.any():
            m = _sel(m)
            q = p[m]
            chan[m] = q.u(2)
            dlc = np.minimum((q + 11).u(1), 8)
            raw = (q + 16).u(4)
            b.can_id[m] = raw & 0x1FFFFFFF
            b.flags[m] = FLAG_ERR | np.where(raw & 0x80000000, FLAG_EXT, 0)
            b.dlc[m] = dlc
            b.data[m] = (q + 24).bytes8(dlc)

        m = kind == CAN_FD_MESSAGE
        if m.any():
            m = _sel(m)
            q = p[m]
            chan[m] = q.u(2)
            fl = (q + 2).u(1)
            code = (q + 3).u(1) & 0x0F
            raw = (q + 4).u(4)
            fd = (q + 13).u(1)
            valid = np.minimum((q + 14).u(1), 64)
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
            b.data[m] = (q + 20).bytes8(valid)
            self._long(b, buf, np.arange(n)[m], (q + 20).at, valid, valid)

        m = kind == CAN_FD_MESSAGE_64
        if m.any():
            m = _sel(m)
            q = p[m]
            chan[m] = q.u(1)
            code = (q + 1).u(1) & 0x0F
            valid = np.minimum((q + 2).u(1), 64).astype(np.int64)
            raw = (q + 4).u(4)
            fd = (q + 12).u(4)
            direction = (q + 34).u(1)
            ext_off = (q + 35).u(1).astype(np.int64)
            # python-can issue 1905: valid_bytes may exceed the bytes stored; pad with zeros.
            # An extension offset beyond the object bounds nothing: the payload ends with it.
            room = np.minimum(np.where(ext_off > 0, ext_off, size[m]), size[m]) - hsize[m] - 40
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
            b.data[m] = (q + 40).bytes8(np.minimum(stored, 8))
            self._long(b, buf, np.arange(n)[m], (q + 40).at, stored, valid)

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
        if len(chan) and chan.min() == chan.max():  # the usual single-channel log
            out[:] = channel_index(self.channels, self._chan, str(int(chan[0])))
            return out
        for c in np.unique(chan).tolist():
            out[chan == c] = channel_index(self.channels, self._chan, str(c))
        return out


def _inflate(payload, limit: int, size: int = 0) -> tuple[bytes, str | None]:
    """zlib-inflate at most ``limit`` bytes; the error text if it is broken or too big.
    ``size``: what the container says it inflates to (a hint, never trusted).

    A whole, sound container (nearly all) is inflated by python-isal when it is
    installed; anything else is redone by `zlib`, whose outcome and error texts
    are the reference, so both give the same bytes and the same problems.
    """
    if _fast_zlib is not None and 0 < size <= limit and len(payload) * _DEFLATE_RATIO <= limit:
        # in one call into a buffer of the size the container declares: no regrowth
        # copies (a stream object grows its output step by step); deflate expands at most
        # _DEFLATE_RATIO times, so neither the output nor a lying size's buffer can pass
        # `limit` or that bound
        try:
            out = _fast_zlib.decompress(payload, 15, min(size, len(payload) * _DEFLATE_RATIO))
        except _fast_zlib.error:
            pass
        else:
            return out, None
    elif _fast_zlib is not None:
        fast = _fast_zlib.decompressobj()
        try:
            out = fast.decompress(payload, limit)
        except _fast_zlib.error:
            pass
        else:
            if fast.eof and not fast.unconsumed_tail:
                return out, None
    z = zlib.decompressobj()
    try:
        out = z.decompress(payload, limit)
    except zlib.error:
        return _salvage(payload, limit)
    if z.unconsumed_tail:
        return out, f"container inflates beyond {limit} bytes (refused)"
    if not z.eof:
        return out, "compressed container is incomplete"
    return out, None


SALVAGE_STEP = 4096  # compressed bytes fed at a time to a broken stream (then one by one)


def _salvage(payload, limit: int) -> tuple[bytes, str]:
    """What a broken zlib stream inflates to before zlib sees the error, and the error.

    zlib raises without the bytes it inflated in that call, and sees the damage late
    (often only at the closing checksum), so the stream is fed again in steps, the
    step that fails once more byte by byte: every byte it gave before the error is
    kept. What the damage turned into garbage before zlib noticed is the object walk's
    to refuse (`_Records`).
    """
    z = zlib.decompressobj()
    parts: list[bytes] = []
    got = at = 0
    n = len(payload)
    err: zlib.error | None = None
    while at < n and err is None and got <= limit:
        chunk = payload[at : at + SALVAGE_STEP]
        before = z.copy()
        try:
            piece = z.decompress(chunk)
        except zlib.error:
            z = before
            for i in range(len(chunk)):
                try:
                    piece = z.decompress(chunk[i : i + 1])
                except zlib.error as e:
                    err, at = e, at + i
                    break
                parts.append(piece)
                got += len(piece)
            continue
        parts.append(piece)
        got += len(piece)
        at += len(chunk)
    out = b"".join(parts)
    if got > limit:  # each step inflates to at most SALVAGE_STEP * _DEFLATE_RATIO bytes
        return out[:limit], f"container inflates beyond {limit} bytes (refused)"
    return out, (
        f"corrupt zlib data ({err}) at byte {at} of its {n} compressed bytes: "
        f"the {got} bytes inflated before it are kept"
    )


class _Libdeflate:
    """libdeflate's whole-buffer zlib inflate, through ctypes, when the system has it.

    It writes straight into the buffer the walk reads (python-isal and zlib return a
    new bytes object, copied there again), and inflates these containers in about
    0.6 of python-isal's time. ctypes releases the GIL for the call. Only a plain
    stream (32 KiB window, no preset dictionary) is taken, and anything it refuses
    is redone by `_inflate`: both give the same bytes and problems. One per read
    (`_Inflated`): a decompressor must not be shared between threads.
    """

    def __init__(self, lib: ctypes.CDLL) -> None:
        self._lib = lib
        self._state = lib.libdeflate_alloc_decompressor()
        if not self._state:
            raise MemoryError("libdeflate_alloc_decompressor failed")
        self._got = ctypes.c_size_t()
        self._got_ref = ctypes.byref(self._got)

    def __del__(self) -> None:
        if getattr(self, "_state", None):
            self._lib.libdeflate_free_decompressor(self._state)
            self._state = None

    def inflate(self, src: bytes, start: int, dest: int, room: int) -> int | None:
        """Inflate ``src[start:]`` (one zlib stream) to address ``dest``, at most
        ``room`` bytes; the bytes written, or None when it is not a sound plain stream
        that fits."""
        if type(src) is not bytes or len(src) < start + 6 or src[start] != 0x78:
            return None  # 0x78: deflate with a 32 KiB window (and the cast needs bytes)
        at = ctypes.cast(src, ctypes.c_void_p).value + start  # type: ignore[operator]
        fn = self._lib.libdeflate_zlib_decompress
        if fn(self._state, at, len(src) - start, dest, room, self._got_ref) != 0:
            return None  # not LIBDEFLATE_SUCCESS: bad data, or more than `room`
        return self._got.value


def _load_libdeflate() -> ctypes.CDLL | None:
    """The system's libdeflate with the signatures used here, or None."""
    try:  # the usual soname first: find_library runs ldconfig (a subprocess) on Linux
        lib = ctypes.CDLL("libdeflate.so.0")
    except OSError:
        name = ctypes.util.find_library("deflate")
        if name is None:
            return None
        try:
            lib = ctypes.CDLL(name)
        except OSError:
            return None
    try:
        lib.libdeflate_alloc_decompressor.restype = ctypes.c_void_p
        lib.libdeflate_alloc_decompressor.argtypes = []
        lib.libdeflate_free_decompressor.restype = None
        lib.libdeflate_free_decompressor.argtypes = [ctypes.c_void_p]
        fn = lib.libdeflate_zlib_decompress
        fn.restype = ctypes.c_int
        fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
        fn.argtypes += [ctypes.c_size_t, ctypes.POINTER(ctypes.c_size_t)]
    except (OSError, AttributeError):  # missing, or too old (no zlib decompress)
        return None
    return lib


_libdeflate = _load_libdeflate()


class _Inflated:
    """Inflated container bytes waiting to be walked together, in one reused buffer.

    A container holds ~2-3k records; parsing each alone cost ~200 us of Python
    and small numpy calls, most of a 10M-frame BLF read, all under the GIL.
    Parsing PARSE_BYTES at once gives the same records (objects that straddle
    containers are joined either way) for a sixteenth of the calls. The buffer
    holds the tail the last walk left (a record continued in the next container)
    and then the containers since, inflated into it in place (`_libdeflate`) or
    copied in: no joining, and no fresh pages for every 2 MiB. `_spans` says which
    container each byte came from, for the problems of the walk.
    """

    def __init__(self, records: _Records) -> None:
        self.records = records
        self.fill = 0  # bytes in the buffer: the tail, then the containers since
        self.size = 0  # bytes of containers since the last walk
        self.pieces = 0  # containers since the last walk
        # (buffer position, container file offset, byte of its data there), ascending
        self._spans: list[tuple[int, int, int]] = []
        self.broken = False  # the last container's zlib stream is broken (not cut short)
        self.cut: tuple | None = None  # what `trim` cut: (where, bytes, reason, a, b, c)
        self._alloc(PARSE_BYTES + (1 << 20))
        self._libdeflate = _Libdeflate(_libdeflate) if _libdeflate is not None else None

    def _alloc(self, n: int) -> None:
        buf = bytearray(n)
        if self.fill:
            buf[: self.fill] = self.view[: self.fill]
        self.buf = buf
        self.view = memoryview(buf)
        # the address pins the buffer (it is never resized, only replaced)
        self._pin = ctypes.c_char.from_buffer(buf)
        self.addr = ctypes.addressof(self._pin)

    def _room(self, n: int) -> None:
        if self.fill + n > len(self.buf):
            self._alloc(max(2 * len(self.buf), self.fill + n))

    def add(self, data, offset: int = 0) -> None:
        """Copy the bytes of the container at file offset ``offset`` in (stored plain, or
        inflated elsewhere)."""
        k = len(data)
        self._room(k)
        self.view[self.fill : self.fill + k] = data
        self._added(k, offset)

    def _added(self, k: int, offset: int) -> None:
        self._spans.append((self.fill, offset, 0))
        self.fill += k
        self.size += k
        self.pieces += 1

    def inflate(self, body: bytes, start: int, size: int, offset: int = 0) -> str | None:
        """Inflate the zlib stream at ``body[start:]`` (the container at file offset
        ``offset``) in; the error text if it is broken or too big (`_inflate`: what it
        inflated to before is kept). ``size``: what the container says it inflates to."""
        n = len(body) - start
        if (
            self._libdeflate is not None
            and 0 < size <= MAX_CONTAINER
            and n * _DEFLATE_RATIO <= MAX_CONTAINER
        ):
            room = min(size, n * _DEFLATE_RATIO)  # bounded as in `_inflate`
            self._room(room)
            got = self._libdeflate.inflate(body, start, self.addr + self.fill, room)
            if got is not None:
                self._added(got, offset)
                return None
        data, err = _inflate(memoryview(body)[start:], MAX_CONTAINER, size)
        self.add(data, offset)
        self.broken = err is not None and not err.startswith("container inflates beyond")
        return err

    def flush(self, batches: _Cutter, final: bool = False, upto: int | None = None) -> int:
        """Walk the bytes in; ``final``: no bytes follow them (the end of the file, or
        a container lost or broken after them), so nothing is kept for the next walk.
        ``upto``: walk only the bytes before this position (the rest joins the tail).
        Returns how many bytes were walked (the tail moved that far down)."""
        if not (self.fill if final else self.pieces):
            return 0
        end = self.fill if upto is None else upto
        pos = self.records.parse(self.view[:end], batches, final, self._where)
        tail = bytes(self.view[pos : self.fill])
        self.view[: len(tail)] = tail
        self.fill = len(tail)
        self.size = self.pieces = 0
        spans = [(max(b - pos, 0), off, k + max(pos - b, 0)) for b, off, k in self._spans]
        firsts = [i for i, sp in enumerate(spans) if sp[0] == 0]  # spans now before the tail
        self._spans = spans[firsts[-1] :] if firsts and tail else []
        return pos

    def trim(self, start: int) -> None:
        """Cut the data of a container whose zlib stream is broken (from ``start`` in
        the buffer) where it stops being believable.

        A damaged deflate stream goes on inflating, often to the end, before zlib sees
        the error (or only its checksum is wrong): from the damage on it repeats
        earlier bytes and mixes them up, giving objects of the right shape whose times,
        identifiers and data are made up. So the data is believed up to the first sign
        of the damage: an object the walk would refuse, or a CAN record more than
        DAMAGED_BACK before or DAMAGED_GAP after the record before it; the object
        before that sign goes too when it came from this container (the damage may
        have begun inside it). The rest is one run of skipped bytes.
        """
        buf = bytes(self.view[: self.fill])
        end = len(buf)
        rec = self.records
        pos, last = 0, None  # the object before, its (start, end); the last record's time
        prev = (-1, -1)
        sign = None
        unpack = _OBJ_BASE.unpack_from
        while pos + 16 <= end:
            if buf[pos : pos + 4] != b"LOBJ":
                nxt = buf.find(b"LOBJ", pos, pos + 8)  # objects are padded to 4 bytes
                if nxt < 0:
                    if pos >= start:
                        sign = (pos, _GARBAGE, 0, 0, 0)
                        break
                    nxt = buf.find(b"LOBJ", pos)
                    if nxt < 0:
                        break
                pos = nxt
                if pos + 16 > end:
                    break
            _, hsize, hver, size, kind = unpack(buf, pos)
            bad = _judge(hsize, hver, size, kind)
            if bad is None and pos + size > end:
                break  # the end of the data (the walk reports an object cut short)
            if bad is None and kind in _WANTED:
                flags, version, stamp = struct.unpack_from("<L2xHq", buf, pos + 16)
                t = stamp * (1e-5 if flags == 1 else 1e-9)
                if not rec.lo <= t <= rec.hi and rec.lo == rec.lo:
                    bad = (_BAD_TIME, kind, int(t), 0)
                elif last is not None and not last - DAMAGED_BACK <= t <= last + DAMAGED_GAP:
                    bad = (_OUT_OF_STEP, kind, int(t), int((t - last) * 1000))
                elif version or not _frame_shaped(buf, pos + hsize, kind):
                    bad = (_OUT_OF_SHAPE, kind, 0, 0)
                last = t
            if bad is not None:
                if pos >= start:
                    sign = (pos, *bad)
                    break
                pos += 4
                continue
            prev = (pos, pos + size)
            pos += size
        if sign is None:
            return
        cut = prev[0] if prev[1] > start and sign[0] - prev[1] < 8 else sign[0]
        cut = max(cut, 0)
        self.cut = (self._where(cut), end - cut, *sign[1:])
        self.fill = cut

    def _where(self, pos: int) -> tuple[int, int]:
        """The file offset of the container buffer byte ``pos`` came from, and which
        byte of its data it is."""
        i = bisect.bisect_right(self._spans, (pos, 1 << 62)) - 1
        b, offset, k = self._spans[max(i, 0)]
        return offset, k + pos - b


_COLUMNS = ("t", "can_id", "flags", "dlc", "data", "channel", "line")


class _Cutter:
    """Parsed rows cut into batches of exactly `size` rows (the last one shorter).

    Rows are written into the batch being filled: by the compiled walk directly
    (`room`, `commit`), else copied from a parsed batch (`add`); never joined and cut
    again.
    """

    def __init__(self, size: int) -> None:
        self.size = max(1, int(size))
        self.cur: FrameBatch | None = None
        self.fill = 0  # rows of `cur` written
        self.ready: list[FrameBatch] = []

    def _current(self) -> FrameBatch:
        if self.cur is None:  # every row is written before the batch is given out
            n = self.size
            self.cur = FrameBatch(
                t=np.empty(n, np.float64),
                can_id=np.empty(n, np.uint32),
                flags=np.empty(n, np.uint8),
                dlc=np.empty(n, np.uint8),
                data=np.empty((n, 8), np.uint8),
                channel=np.empty(n, np.uint16),
                line=np.empty(n, np.int64),
            )
            self.fill = 0
        return self.cur

    def _advance(self, n: int, channels: tuple[str, ...]) -> None:
        self.fill += n
        if len(channels) >= len(self.cur.channels):  # type: ignore[union-attr]
            self.cur.channels = channels  # type: ignore[union-attr]  # tables only grow
        if self.fill == self.size:
            self.ready.append(self.cur)  # type: ignore[arg-type]
            self.cur = None

    def room(self, rows: int) -> tuple[FrameBatch, int] | None:
        """The batch being filled and its first free row, when `rows` more fit in it."""
        b = self._current()
        return (b, self.fill) if self.size - self.fill >= rows else None

    def commit(self, n: int, channels: tuple[str, ...], long: dict[int, bytes]) -> None:
        """`n` rows were written at the first free row (`room`); `long`: by their row there."""
        b = self.cur
        for row, payload in long.items():
            b.long_data[self.fill + row] = payload  # type: ignore[union-attr]
        self._advance(n, channels)

    def add(self, batch: FrameBatch) -> None:
        """Copy the rows of a parsed batch in."""
        n, i = len(batch), 0
        while i < n:
            b = self._current()
            k = min(n - i, self.size - self.fill)
            for col in _COLUMNS:
                getattr(b, col)[self.fill : self.fill + k] = getattr(batch, col)[i : i + k]
            for row, payload in batch.long_data.items():
                if i <= row < i + k:
                    b.long_data[self.fill + row - i] = payload
            self._advance(k, batch.channels)
            i += k

    def full(self) -> Iterator[FrameBatch]:
        ready, self.ready = self.ready, []
        yield from ready

    def rest(self) -> Iterator[FrameBatch]:
        if self.cur is not None and self.fill:
            b, self.cur = self.cur.take(slice(0, self.fill)), None
            yield b


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
    stream = _Pushback(stream)
    rest = max(0, fields[1] - _FILE_HEADER.size)
    if rest > MAX_FILE_HEADER:  # one read of a claimed 2 GB header was a MemoryError
        ctx.problems.add(
            ctx.source,
            "offset 4",
            f"BLF file header claims {fields[1]} bytes (refused); objects are looked for after it",
        )
        rest = 0
    if len(stream.read(rest)) < rest:
        ctx.problems.add(
            ctx.source, f"offset {_FILE_HEADER.size}", "file ends inside the BLF file header"
        )
        return
    offset = _FILE_HEADER.size + rest
    declared_size = fields[10]  # 0 when the logger never closed the file
    stop = _systemtime(fields[22:30])
    if start is not None and stop is not None and stop >= start:
        lo, hi = -TIME_SLACK, stop - start + TIME_SLACK
    elif start is not None:  # the logger never closed the file
        lo, hi = -TIME_SLACK, MAX_SPAN
    else:  # a range around the first record's time (`_Records`)
        lo = hi = math.nan
    records = _Records(ctx, start or 0.0, lo, hi)
    inflated = _Inflated(records)
    batches = _Cutter(ctx.batch_size)

    resynced = False  # the object read next was found by looking for its signature

    def problem(where: str, text: str, upto: int | None = None) -> None:
        """A problem at the top level: what came before it (before ``upto`` in the
        buffer: the data of the container it is about) is walked and reported first;
        the bytes after it no longer continue the data before, so what is left of them
        is walked to the end (`final`), a broken zlib stream's only as far as it is
        believable (`_Inflated.trim`)."""
        walked = inflated.flush(batches, upto=upto)
        ctx.problems.add(ctx.source, where, text)
        if upto is not None and inflated.broken:
            inflated.trim(upto - walked)
        inflated.flush(batches, final=True)
        if inflated.cut is not None:
            records.report_cut(*inflated.cut)
            inflated.cut = None

    while True:
        base = stream.read(16)
        if not base:
            if (
                declared_size > offset
            ):  # ends cleanly between objects, but short of its own header's size
                problem(
                    f"offset {offset}",
                    f"file ends here but its header says {declared_size} bytes (cut short?)",
                )
            break
        where = f"offset {offset}"
        if len(base) < 16:
            problem(where, f"file ends inside an object header ({len(base)} bytes)")
            break
        sig, _, _, size, kind = _OBJ_BASE.unpack(base)
        if sig != b"LOBJ" or size < 16 or size > MAX_CONTAINER:
            # resynchronise on the next signature (python-can stops here: half a log lost)
            skipped = stream.skip_to(b"LOBJ", base, 1)
            what = "no BLF object (LOBJ)" if sig != b"LOBJ" else f"BLF object size {size} is absurd"
            problem(where, f"{what}: skipped {skipped} bytes to the next object")
            offset += skipped
            resynced = True
            continue
        if resynced and kind != LOG_CONTAINER:
            # an object inside the data of a plain container whose header is lost: that
            # data, up to the next container, is walked like a container's (it goes on
            # into the next one's)
            data = stream.read_to_container(base, MAX_CONTAINER)
            inflated.add(data, offset)
            offset += len(data)
            if inflated.size >= PARSE_BYTES:
                inflated.flush(batches)
            yield from batches.full()
            continue
        resynced = False
        body = stream.read(size - 16)
        stream.read(size % 4)  # padding
        offset += size + size % 4
        truncated = len(body) < size - 16
        if kind != LOG_CONTAINER:
            if truncated:
                problem(where, "file ends inside an object")
                break
            continue
        if len(body) < _CONTAINER.size:
            problem(where, "file ends inside a container header")
            break
        method, usize = _CONTAINER.unpack_from(body)
        mark = inflated.fill
        at = offset - size - size % 4  # this container's
        if method == 0:
            inflated.add(memoryview(body)[_CONTAINER.size :], at)
            err = None
        elif method == 2:
            err = inflated.inflate(body, _CONTAINER.size, usize, at)
        else:
            problem(where, f"unknown container compression {method}, skipped")
            continue
        if truncated:
            err = f"file ends inside a container ({len(body) + 16} of {size} bytes)"
        if err:  # what it inflated to before the damage is walked, what follows is not joined
            problem(where, err, mark)
        elif inflated.size >= PARSE_BYTES:
            inflated.flush(batches)
        yield from batches.full()
        if truncated:
            break
    inflated.flush(batches, final=True)
    yield from batches.full()
    yield from batches.rest()


class _Pushback:
    """The file stream with bytes put back, for resynchronising on a signature."""

    def __init__(self, stream: BinaryIO) -> None:
        self._stream = stream
        self._back = b""

    def read(self, n: int) -> bytes:
        if not self._back:
            return self._stream.read(n)
        head, self._back = self._back[:n], self._back[n:]
        return head + self._stream.read(n - len(head)) if len(head) < n else head

    def read_to_container(self, head: bytes, limit: int) -> bytes:
        """The bytes from ``head`` (read already; not a container's header) up to the next
        container header (its signature, type LOG_CONTAINER and a size it may have), at
        most ``limit`` of them; the rest is put back."""
        buf = bytearray(head)
        at = 1
        while True:
            at = buf.find(b"LOBJ", at)
            while 0 <= at <= len(buf) - 16:
                _, _, _, size, kind = _OBJ_BASE.unpack_from(buf, at)
                if kind == LOG_CONTAINER and _CONTAINER.size + 16 <= size <= MAX_CONTAINER:
                    self._back = bytes(buf[at:]) + self._back
                    return bytes(buf[:at])
                at = buf.find(b"LOBJ", at + 1)
            at = max(len(buf) - 15, 1) if at < 0 else at  # a header may straddle the next read
            if len(buf) >= limit:
                self._back = bytes(buf[limit:]) + self._back
                return bytes(buf[:limit])
            more = self.read(1 << 16)
            if not more:
                return bytes(buf)
            buf += more

    def skip_to(self, sig: bytes, consumed: bytes, start: int) -> int:
        """Drop bytes up to the next `sig` at or after `start` in `consumed` (bytes read
        already) and put the rest back, so the next read starts at the signature; reads
        in 64 KiB steps. Returns how many bytes were dropped."""
        buf, base, pos = consumed, 0, start
        while True:
            at = buf.find(sig, pos)
            if at >= 0:
                self._back = buf[at:] + self._back
                return base + at
            cut = max(0, len(buf) - (len(sig) - 1))
            base, buf, pos = base + cut, buf[cut:], 0
            more = self.read(1 << 16)
            if not more:
                return base + len(buf)
            buf += more


class BlfWriter(PycanWriter):
    """python-can's BLFWriter, the reference for the format."""

    def __init__(self, path: Path) -> None:
        import can

        super().__init__(path, can.BLFWriter)

    def flush(self) -> None:
        # python-can's BLFWriter keeps frames until a 128 KiB container is full and has no
        # public flush: its _flush writes one container of what it holds
        if self._writer is not None:
            while self._writer._buffer_size:
                self._writer._flush()
        super().flush()


FORMAT = register(
    LogFormat(
        name="blf",
        description="Vector BLF binary log",
        sniff=sniff,
        read=read,
        suffixes=(".blf",),
        priority=11,
        text=False,
        write_suffix=".blf",
        writer=BlfWriter,
    )
)
