"""Wireshark/tcpdump captures of SocketCAN: pcap and pcapng, read as columns.

Link types: 227 LINKTYPE_CAN_SOCKETCAN (a `struct can_frame` / `canfd_frame` per
packet, identifier word in network byte order) and the Linux cooked captures
LINKTYPE_LINUX_SLL (113) and SLL2 (276) of CAN (protocol 0x000C/0x000D, the frame in
host byte order, as the kernel hands it to the capture; x86 and ARM are
little-endian). No library here reads pcap as columns: python-can has no pcap
reader, dpkt and scapy build a Python object per packet. Packet records are
found by one shift per run of records of one size (a capture of classic frames is
all one size), the frame fields then read with numpy gathers.

Every length read from the file is bounded before anything is allocated: a pcap
record over MAX_RECORD or its snap length, a pcapng block over MAX_BLOCK, is not
read. Damage never becomes a frame and does not end the read (docs/hostile-input.md):
a pcap record is believed when its header is plausible (lengths it may have, a
fraction under a second, a time close to the record before it) and so is the header
after it; a pcapng block when its leading and trailing lengths agree. After one that
is not, the reader looks for the next plausible record or block (`_PcapHeaders.scan`,
`_pcapng_scan`) and goes on from there, with one problem naming the offset and the
bytes skipped.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from cananalyze.core.errors import InputError
from cananalyze.core.frames import (
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
from cananalyze.formats.logs.blf import _Cutter
from cananalyze.formats.logs.echoes import EchoFilter
from cananalyze.formats.registry import LogFormat, ReadContext, register

LINKTYPE_CAN_SOCKETCAN = 227
LINKTYPE_LINUX_SLL = 113
LINKTYPE_LINUX_SLL2 = 276
LINK_NAMES = {
    1: "Ethernet",
    101: "raw IP",
    113: "Linux cooked (SLL)",
    127: "802.11 radiotap",
    227: "SocketCAN",
    276: "Linux cooked v2 (SLL2)",
}
ETH_P_CAN, ETH_P_CANFD = 0x000C, 0x000D
PACKET_OUTGOING = 4

MAX_RECORD = 256 << 10  # a CAN packet is at most 92 bytes; other packets up to this are skipped
MAX_BLOCK = 16 << 20  # pcapng blocks: interface descriptions and packets, never near this
CHUNK = 8 << 20  # bytes read at a time
# A pcap record is believed when its time is within TIME_STEP of the record before's, or
# up to MAX_JUMP after it when the record after it is within TIME_STEP of it (the
# capture's clock jumped); one found again after damage holds MIN_FOUND bytes or more
# (a CAN frame's header), and is whole when the records before were.
TIME_STEP = 86400  # s
MAX_JUMP = 366 * 86400  # s
MIN_FOUND = 8
SCAN_WINDOW = 1 << 20  # bytes looked at in one go when looking for the next record or block

_PCAP_MAGIC = {
    b"\xd4\xc3\xb2\xa1": ("<", 1e-6),
    b"\xa1\xb2\xc3\xd4": (">", 1e-6),
    b"\x4d\x3c\xb2\xa1": ("<", 1e-9),
    b"\xa1\xb2\x3c\x4d": (">", 1e-9),
}
_SHB = 0x0A0D0D0A
_IDB, _EPB, _SPB, _OPB = 1, 6, 3, 2
# block types of the pcapng specification, and the shortest each can be
_KNOWN_BLOCKS = (_SHB, _IDB, _OPB, _SPB, 4, 5, _EPB, 9, 10, 0x00000BAD, 0x40000BAD)
_MIN_BLOCK = {_SHB: 28, _IDB: 20, _EPB: 32, _SPB: 16, _OPB: 32, 5: 24}
_BYTE_ORDER = {b"\x4d\x3c\x2b\x1a": "<", b"\x1a\x2b\x3c\x4d": ">"}


def sniff(head: bytes) -> bool:
    return head[:4] in _PCAP_MAGIC or (
        head[:4] == b"\x0a\x0d\x0d\x0a" and head[8:12] in (b"\x4d\x3c\x2b\x1a", b"\x1a\x2b\x3c\x4d")
    )


class _Frames:
    """The CAN frames of runs of packets (one matrix row each) as FrameBatch columns, and
    what was skipped: packets of another protocol, packets cut short."""

    def __init__(self, ctx: ReadContext) -> None:
        self.ctx = ctx
        self.channels: list[str] = []
        self.not_can = 0  # packets of another protocol in a cooked capture
        self.cut = 0  # packets captured shorter than their frame
        self.record = 0

    def channel(self, name: str) -> int:
        if name not in self.channels:
            self.channels.append(name)
        return self.channels.index(name)

    def batch(
        self,
        rows: np.ndarray,  # (n, width) uint8: each packet's bytes from its first, zero padded
        caplen: np.ndarray,
        t: np.ndarray,
        link: int,
        channel: int,
        index: np.ndarray | None = None,  # the rows' places in the run (default: in order)
    ) -> FrameBatch | None:
        """Record numbers (`line`) count from `self.record`, which the caller advances."""
        n = rows.shape[0]
        if n == 0:
            return None
        caplen = caplen.astype(np.int64)
        ok = np.ones(n, bool)
        tx = None
        if link in (LINKTYPE_LINUX_SLL, LINKTYPE_LINUX_SLL2):
            hdr = 16 if link == LINKTYPE_LINUX_SLL else 20
            p = 14 if link == LINKTYPE_LINUX_SLL else 0
            proto = (rows[:, p].astype(np.int64) << 8) | rows[:, p + 1]
            ok = (caplen >= hdr) & ((proto == ETH_P_CAN) | (proto == ETH_P_CANFD))
            tx = rows[:, 1 if link == LINKTYPE_LINUX_SLL else 10] == PACKET_OUTGOING
            self.not_can += int(n - np.count_nonzero(ok))
            rows, caplen = rows[:, hdr:], caplen - hdr
        whole = caplen >= 8  # the identifier word, length and flags at least
        self.cut += int(np.count_nonzero(ok & ~whole))
        ok &= whole
        keep = None if ok.all() else np.flatnonzero(ok)
        if keep is not None:
            rows, caplen, t = rows[keep], caplen[keep], t[keep]
            tx = tx[keep] if tx is not None else None
        m = rows.shape[0]
        if rows.shape[1] < 16:  # records cut after their data: pad to the 8 data bytes
            rows = np.pad(rows, ((0, 0), (0, 16 - rows.shape[1])))
        word = _col(rows, 0, ">u4" if link == LINKTYPE_CAN_SOCKETCAN else "<u4")
        length = rows[:, 4]
        fdflags = rows[:, 5]
        fd = ((fdflags & 0x04) != 0) | (caplen >= 72) | (length > 8)
        any_fd = bool(fd.any())
        if any_fd:
            length = np.minimum(length, np.where(fd, 64, 8)).astype(np.uint8)
        else:
            length = np.minimum(length, 8)
        have = np.minimum(caplen - 8, 255).astype(np.uint8)  # bytes captured after the header
        short = have < length
        if short.any():
            self.cut += int(np.count_nonzero(short))
            length = np.minimum(length, have)
        fb = FrameBatch.allocate(m)
        fb.t[:] = t
        top = (word >> np.uint32(29)).astype(np.uint8)  # EFF, RTR, ERR bits
        ext, remote, err = (top & 4) != 0, (top & 2) != 0, (top & 1) != 0
        remote &= ~err
        flags = fb.flags
        flags |= (ext & ~err).view(np.uint8) * np.uint8(FLAG_EXT)
        flags |= err.view(np.uint8) * np.uint8(FLAG_ERR)
        flags |= remote.view(np.uint8) * np.uint8(FLAG_RTR)
        if any_fd:
            flags |= fd.view(np.uint8) * np.uint8(FLAG_FD)
            flags |= (fd & ((fdflags & 0x01) != 0)).view(np.uint8) * np.uint8(FLAG_BRS)
            flags |= (fd & ((fdflags & 0x02) != 0)).view(np.uint8) * np.uint8(FLAG_ESI)
        if tx is not None:
            flags |= tx.view(np.uint8) * np.uint8(FLAG_TX)
        fb.can_id[:] = word & np.where(ext | err, np.uint32(0x1FFFFFFF), np.uint32(0x7FF))
        stored = np.where(remote, 0, length).astype(np.uint8)
        # a remote request's len field is the DLC it asks for (candump shows it so)
        fb.dlc[:] = np.where(remote, np.minimum(rows[:, 4], 8), length)
        # the 8 data bytes as one little-endian word, the bytes past the length cleared
        words = rows[:, 8:16].view("<u8")[:, 0]
        fb.data[:] = (words & _KEEP8[np.minimum(stored, 8)]).view(np.uint8).reshape(m, 8)
        for r in np.flatnonzero(stored > 8).tolist():
            fb.long_data[r] = rows[r, 8 : 8 + int(stored[r])].tobytes()
        fb.channel[:] = channel
        at = np.arange(n) if index is None else index
        fb.line[:] = self.record + 1 + (at if keep is None else at[keep])
        fb.channels = tuple(self.channels)
        return fb


_KEEP8 = np.array([(1 << (8 * k)) - 1 for k in range(9)], np.uint64)  # first k bytes


def _col(rows: np.ndarray, at: int, dtype: str) -> np.ndarray:
    """A 4-byte field of every row (a column of the record matrix): a strided view."""
    return rows[:, at : at + 4].view(dtype)[:, 0]


def _run(buf: np.ndarray, pos: int, count: int, size: int) -> np.ndarray:
    """`count` records of `size` bytes from `pos` as a (count, size) matrix (a view)."""
    return buf[pos : pos + count * size].reshape(count, size)


def _uniform(
    buf: np.ndarray, pos: int, size: int, order: str, length_at: int, add: int, kind: int | None
) -> int:
    """How many records of `size` bytes follow each other from `pos` (at least 1): each
    one's length field (u32 at `length_at`, plus `add`) says `size`, and for pcapng its
    block type is `kind`. A short window first, so a file of mixed sizes costs little."""
    avail = (len(buf) - pos) // size
    for n in (min(avail, 256), avail):
        if n <= 1:
            return 1
        rec = _run(buf, pos, n, size)
        same = _col(rec, length_at, order + "u4").astype(np.int64) + add == size
        if kind is not None:
            same &= _col(rec, 0, order + "u4") == kind
        bad = np.flatnonzero(~same)
        if bad.size:
            return max(int(bad[0]), 1)
    return max(avail, 1)


def _u32_each(b: np.ndarray, order: str) -> np.ndarray:
    """The uint32 starting at each byte of ``b`` (len(b) - 3 of them), as int64."""
    w = b.astype(np.int64)
    n = len(b) - 3
    if order == "<":
        return w[:n] | w[1 : n + 1] << 8 | w[2 : n + 2] << 16 | w[3 : n + 3] << 24
    return w[:n] << 24 | w[1 : n + 1] << 16 | w[2 : n + 2] << 8 | w[3 : n + 3]


class _PcapHeaders:
    """What a pcap record header must look like to be believed, and where the next one
    is after damage."""

    def __init__(self, order: str, limit: int, frac_max: int, link: int) -> None:
        self.head = struct.Struct(order + "IIII")  # seconds, fraction, captured, on the wire
        self.order = order
        self.limit = limit
        self.frac_max = frac_max
        # where a CAN frame starts in a packet, its protocol field (cooked captures)
        self.frame_at = {LINKTYPE_LINUX_SLL: 16, LINKTYPE_LINUX_SLL2: 20}.get(link, 0)
        self.proto_at = {LINKTYPE_LINUX_SLL: 14, LINKTYPE_LINUX_SLL2: 0}.get(link)
        self.whole = True  # the last record believed was captured whole

    def _sane(self, frac: int, incl: int, orig: int) -> bool:
        return incl <= self.limit and incl <= orig <= MAX_RECORD and frac < self.frac_max

    def plausible(self, raw: bytes, p: int, prev: int | None, ended: bool) -> bool | None:
        """Whether the record header at ``p`` is believed after a record of second
        ``prev`` (None: none before it); None when that takes bytes not read yet."""
        sec, frac, incl, orig = self.head.unpack_from(raw, p)
        if not self._sane(frac, incl, orig):
            return False
        if prev is None or abs(sec - prev) <= TIME_STEP:
            return True
        if not 0 < sec - prev <= MAX_JUMP or incl < MIN_FOUND:
            return False
        return self._followed(raw, p, sec, incl, ended)  # the clock jumped ahead

    def _followed(self, raw: bytes, p: int, sec: int, incl: int, ended: bool) -> bool | None:
        """Whether a plausible record within TIME_STEP follows the one at ``p``."""
        nxt = p + 16 + incl
        if nxt + 16 > len(raw):
            return False if ended else None
        sec2, frac2, incl2, orig2 = self.head.unpack_from(raw, nxt)
        return self._sane(frac2, incl2, orig2) and abs(sec2 - sec) <= TIME_STEP

    def far(self, raw: bytes, p: int, prev: int) -> bool:
        """Whether the time at ``p`` is far from ``prev``: the damage took the header's
        time too, so the record before it may be damaged as well."""
        return abs(self.head.unpack_from(raw, p)[0] - prev) > TIME_STEP

    def why(self, raw: bytes, p: int, prev: int | None) -> str:
        sec, frac, incl, orig = self.head.unpack_from(raw, p)
        if incl > self.limit:
            return f"pcap record of {incl} bytes is longer than its snap length {self.limit}"
        if not incl <= orig <= MAX_RECORD:
            return f"pcap record of {incl} bytes says it was {orig} bytes long"
        if frac >= self.frac_max:
            return f"pcap record's fraction of a second is {frac}"
        return f"pcap record at {sec} s is far from the one before it at {prev} s"

    def _candidate(self, raw: bytes, p: int, prev: int | None, ended: bool) -> bool | None:
        """Whether a record found at ``p`` while resynchronising is believed: a CAN frame
        (or a whole one, when the records before were) followed by a plausible record
        or by the end of the file; None when that takes bytes not read yet."""
        sec, frac, incl, orig = self.head.unpack_from(raw, p)
        if (self.whole and incl != orig) or incl < self.frame_at + 8:
            return False
        if p + 16 + incl > len(raw):
            return False if ended else None
        if self.proto_at is not None:
            proto = raw[p + 16 + self.proto_at] << 8 | raw[p + 17 + self.proto_at]
            if proto not in (ETH_P_CAN, ETH_P_CANFD):
                return False
        if raw[p + 20 + self.frame_at] > incl - self.frame_at - 8:  # the frame's length byte
            return False
        if p + 16 + incl == len(raw) and ended:
            return prev is None or abs(sec - prev) <= TIME_STEP
        return self._followed(raw, p, sec, incl, ended)

    def scan(
        self, raw: bytes, buf: np.ndarray, start: int, prev: int | None, ended: bool
    ) -> tuple[int | None, int]:
        """(where the next believable record is from ``start``, or None; where to go on
        looking when it is None: bytes from there may start one and need more read)."""
        end = len(raw)
        s = start
        while s + 16 <= end:
            e = min(s + SCAN_WINDOW, end - 15)
            u = _u32_each(buf[s : e + 15], self.order)
            m = e - s
            sec, frac, incl, orig = u[:m], u[4 : m + 4], u[8 : m + 8], u[12 : m + 12]
            ok = (incl >= MIN_FOUND) & (incl <= self.limit) & (orig >= incl)
            ok &= (orig <= MAX_RECORD) & (frac < self.frac_max)
            if prev is not None:
                ok &= (sec - prev >= -TIME_STEP) & (sec - prev <= MAX_JUMP)
            for c in (np.flatnonzero(ok) + s).tolist():
                found = self._candidate(raw, c, prev, ended)
                if found is None:
                    return None, c
                if found:
                    return c, c
            s = e
        return None, max(s, start)


def _skipped(
    ctx: ReadContext, skip: tuple[int, str], to: int, where: str, unit: str, resync: str
) -> None:
    """One warning for the bytes a resynchronising reader skipped, [skip's offset, to):
    `unit` is a record or block, `resync` the `where` of a jump to the next plausible one.
    No reason: a unit running past the end, the file cut short (or its length field)."""
    at, why = skip
    if not why:
        if where != resync:
            text = f"file ends inside a {unit} ({to - at} bytes)"
            ctx.problems.add(ctx.source, f"offset {at}", text)
            return
        why = f"{unit} runs past the end of the file"
    ctx.problems.add(
        ctx.source, f"offset {at}", f"{why} (corrupt file): skipped {to - at} bytes {where}"
    )


def _read_pcap(stream: BinaryIO, ctx: ReadContext, head: bytes) -> Iterator[FrameBatch]:
    order, unit = _PCAP_MAGIC[head[:4]]
    if len(head) < 24:
        ctx.problems.add(ctx.source, "offset 0", "file ends inside the pcap header")
        return
    _vmaj, _vmin, _zone, _sig, snaplen, link = struct.unpack(order + "HHiIII", head[4:24])
    link &= 0x0FFFFFFF  # the upper bits hold the FCS length
    if link not in (LINKTYPE_CAN_SOCKETCAN, LINKTYPE_LINUX_SLL, LINKTYPE_LINUX_SLL2):
        _other_link(ctx, link)
        return
    ctx.format = "pcap"
    ctx.absolute_time = True
    frames = _Frames(ctx)
    chan0 = frames.channel("pcap")
    limit = min(max(snaplen, 0) or MAX_RECORD, MAX_RECORD)
    hdr = _PcapHeaders(order, limit, 1_000_000 if unit == 1e-6 else 1_000_000_000, link)
    dt = order + "u4"
    cutter = _Cutter(ctx.batch_size)
    rest = b""
    offset = 24  # file offset of rest[0]
    ended = False
    prev: int | None = None  # the second of the last record believed
    skip: tuple[int, str] | None = None  # resynchronising: (file offset skipped from, why)
    judged = -1  # the position whose header was found plausible already

    def skipped(to: int, where: str) -> None:
        _skipped(ctx, skip, to, where, "pcap record", "to the next plausible record")

    while not ended:
        data = stream.read(CHUNK)
        ended = not data
        raw = rest + data
        buf = np.frombuffer(raw, np.uint8)
        pos = 0
        while pos + 16 <= len(raw):
            if skip is not None:
                found, pos = hdr.scan(raw, buf, pos, prev, ended)
                if found is None:
                    break  # none in these bytes: go on with the next ones
                skipped(offset + found, "to the next plausible record")
                skip, judged = None, found
                prev = hdr.head.unpack_from(raw, found)[0]
                continue
            ok = True if pos == judged else hdr.plausible(raw, pos, prev, ended)
            if ok is None:
                break
            incl = hdr.head.unpack_from(raw, pos)[2]
            size = 16 + incl
            if not ok or pos + size > len(raw):
                if ok and not ended:
                    break
                why = hdr.why(raw, pos, prev) if ok is False else ""  # "": past the end
                skip = (offset + pos, why)
                pos += 1
                continue
            count = _uniform(buf, pos, size, order, 8, 16, None)
            rec = _run(buf, pos, count, size)
            t = _col(rec, 0, dt).astype(np.float64) + _col(rec, 4, dt) * unit
            # each record's time within TIME_STEP of the one before's: two reductions;
            # only when the run spans more, which record it is
            if count > 1 and t.max() - t.min() > TIME_STEP:
                good = np.ones(count, bool)
                good[1:] = np.abs(np.diff(t)) <= TIME_STEP
                count = int(np.argmin(good)) if not good.all() else count
            # and the header after it: else the last record may hold the damage's start
            nxt = pos + count * size
            last = int(_col(rec, 0, dt)[count - 1])
            follows = hdr.plausible(raw, nxt, last, ended) if nxt + 16 <= len(raw) else ended
            later = follows is None or (follows is False and nxt + 16 > len(raw))
            if later:
                count -= 1  # judged with the bytes read next
            elif not follows:
                if hdr.far(raw, nxt, last):  # its time is damaged too: so may the record be
                    count -= 1
                    skip = (offset + pos + count * size, hdr.why(raw, nxt, last))
                else:
                    skip = (offset + nxt, hdr.why(raw, nxt, last))
            judged = nxt if follows else -1
            if count:
                rec = rec[:count]
                fb = frames.batch(rec[:, 16:], np.full(count, incl), t[:count], link, chan0)
                frames.record += count
                if fb is not None:
                    cutter.add(fb)
                    ctx.frames += len(fb)
                prev = last
                hdr.whole = bool(_col(rec, 12, dt)[count - 1] == incl)
            pos += count * size
            if skip is not None:
                pos = (skip[0] - offset) + 1
            elif later:
                break  # the record at pos is judged with more bytes
        yield from cutter.full()
        offset += pos
        rest = raw[pos:]
    if skip is not None:
        skipped(offset + len(rest), "to the end of the file")
    elif rest:
        ctx.problems.add(
            ctx.source, f"offset {offset}", f"file ends inside a pcap record ({len(rest)} bytes)"
        )
    _summary(ctx, frames)
    yield from cutter.rest()


def _link_text(ctx: ReadContext, link: int) -> str:
    name = LINK_NAMES.get(link, "not CAN")
    return (
        f"{ctx.source}: a capture of link type {link} ({name}), not of CAN: cananalyze reads "
        "SocketCAN (227) and Linux cooked captures (113, 276) of CAN"
    )


def _other_link(ctx: ReadContext, link: int) -> None:
    """A capture of another link type is no CAN log at all: one error line."""
    raise InputError(_link_text(ctx, link))


def _summary(ctx: ReadContext, frames: _Frames) -> None:
    if frames.not_can:
        ctx.extras["not_can_packets"] = frames.not_can
    if frames.cut:
        ctx.problems.add(
            ctx.source,
            "packets",
            f"{frames.cut} packets captured shorter than their CAN frame (snap length?): data cut",
        )


class _Interface:
    def __init__(self, link: int, tsres: float, name: str) -> None:
        self.link = link
        self.tsres = tsres
        self.name = name


def _idb_options(body: bytes, order: str) -> tuple[float, str | None]:
    """if_tsresol (9) and if_name (2) of an interface description's options."""
    tsres, name, pos = 1e-6, None, 8
    while pos + 4 <= len(body):
        code, size = struct.unpack_from(order + "HH", body, pos)
        value = body[pos + 4 : pos + 4 + size]
        if code == 0:
            break
        if code == 9 and size >= 1:
            r = value[0]
            tsres = 2.0 ** -(r & 0x7F) if r & 0x80 else 10.0 ** -(r & 0x7F)
        elif code == 2:
            name = value.split(b"\0")[0].decode("utf-8", "replace")
        pos += 4 + size + (-size % 4)
    return tsres, name


def _pcapng_scan(
    raw: bytes, start: int, order: str, ended: bool, ifaces: int
) -> tuple[int | None, int]:
    """(where the next believable pcapng block is from ``start``, or None; where to go
    on looking when it is None). Blocks start 4-aligned; one is believed when its type is
    one of the specification's, its length one it may have and its trailing length the
    same (an enhanced packet block's interface declared, when any is)."""
    end = len(raw)
    dt = np.dtype(order + "u4")
    s = start
    while end - s >= 12:
        n = min(SCAN_WINDOW, end - s) // 4
        w = np.frombuffer(raw, dt, count=n, offset=s)
        kinds, sizes = w[:-1], w[1:]
        ok = np.isin(kinds, _KNOWN_BLOCKS) & (sizes >= 12) & (sizes % 4 == 0)
        ok &= sizes <= MAX_BLOCK
        for k in np.flatnonzero(ok).tolist():
            p = s + 4 * k
            kind, size = int(kinds[k]), int(sizes[k])
            if size < _MIN_BLOCK.get(kind, 12):
                continue
            if p + size > end:
                if not ended:
                    return None, p  # judged with the bytes read next
                continue
            if struct.unpack_from(order + "I", raw, p + size - 4)[0] != size:
                continue
            if kind == _SHB and raw[p + 8 : p + 12] not in _BYTE_ORDER:
                continue
            if kind == _EPB and ifaces and struct.unpack_from(order + "I", raw, p + 8)[0] >= ifaces:
                continue
            return p, p
        s += 4 * (n - 1)
    return None, s


def _read_pcapng(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    ctx.format = "pcapng"
    ctx.absolute_time = True
    frames = _Frames(ctx)
    cutter = _Cutter(ctx.batch_size)
    order = "<"
    ifaces: list[_Interface] = []
    warned_link: set[int] = set()
    rest = b""
    offset = 0
    ended = False
    skip: tuple[int, str] | None = None  # resynchronising: (file offset skipped from, why)

    def skipped(to: int, where: str) -> None:
        _skipped(ctx, skip, to, where, "pcapng block", "to the next pcapng block")

    while not ended:
        data = stream.read(CHUNK)
        ended = not data
        raw = rest + data
        buf = np.frombuffer(raw, np.uint8)
        pos = 0
        while pos + 12 <= len(raw):
            if skip is not None:
                found, pos = _pcapng_scan(raw, pos, order, ended, len(ifaces))
                if found is None:
                    break  # none in these bytes: go on with the next ones
                skipped(offset + found, "to the next pcapng block")
                skip = None
                continue
            kind = struct.unpack_from(order + "I", raw, pos)[0]
            why = None
            if kind == _SHB:
                bom = raw[pos + 8 : pos + 12]
                if bom in _BYTE_ORDER:
                    order = _BYTE_ORDER[bom]
                else:
                    why = "bad pcapng byte-order magic"
            size = struct.unpack_from(order + "I", raw, pos + 4)[0]
            if why is None and (size < _MIN_BLOCK.get(kind, 12) or size % 4 or size > MAX_BLOCK):
                why = f"pcapng block of {size} bytes is impossible"
            if why is None and pos + size > len(raw):
                if not ended:
                    break
                why = ""  # runs past the end of the file
            if why is None:
                trailer = struct.unpack_from(order + "I", raw, pos + size - 4)[0]
                if trailer != size:
                    why = f"pcapng block of {size} bytes ends with a length of {trailer}"
            if why is not None:
                skip = (offset + pos, why)
                pos += 4
                continue
            if kind == _EPB:
                count = _uniform(buf, pos, size, order, 4, 0, _EPB)
                rec = _run(buf, pos, count, size)
                if count > 1:  # each block's trailing length the same as its leading one
                    bad = np.flatnonzero(_col(rec, size - 4, order + "u4") != size)
                    if bad.size:
                        count = int(bad[0])
                        rec = rec[:count]
                _epb_run(rec, order, ifaces, frames, cutter, ctx, warned_link)
                pos += count * size
                continue
            body = raw[pos + 8 : pos + size - 4]
            if kind == _SHB:
                ifaces = []  # a new section starts its own interface numbering
            elif kind == _IDB and len(body) >= 8:
                link = struct.unpack_from(order + "H", body, 0)[0]
                tsres, name = _idb_options(body, order)
                ifaces.append(_Interface(link, tsres, name or f"if{len(ifaces)}"))
            elif kind in (_SPB, _OPB):
                ctx.problems.add(
                    ctx.source,
                    f"offset {offset + pos}",
                    "pcapng simple/obsolete packet block skipped (no timestamp or interface)",
                )
            pos += size
        yield from cutter.full()
        offset += pos
        rest = raw[pos:]
    if skip is not None:
        skipped(offset + len(rest), "to the end of the file")
    elif rest:
        ctx.problems.add(
            ctx.source, f"offset {offset}", f"file ends inside a pcapng block ({len(rest)} bytes)"
        )
    if warned_link and not ctx.frames:
        _other_link(ctx, min(warned_link))
    _summary(ctx, frames)
    yield from cutter.rest()


def _epb_run(rec: np.ndarray, order, ifaces, frames: _Frames, cutter, ctx, warned) -> None:
    """A run of enhanced packet blocks of one size, as a (count, size) matrix."""
    dt = order + "u4"
    iface = _col(rec, 8, dt).astype(np.int64)
    ticks = _col(rec, 12, dt).astype(np.float64) * 4294967296.0 + _col(rec, 16, dt)
    caplen = np.minimum(_col(rec, 20, dt).astype(np.int64), rec.shape[1] - 32)  # in the block
    rows = rec[:, 28:]
    parts = []
    kinds = np.unique(iface).tolist()
    for k in kinds:
        sel = slice(None) if len(kinds) == 1 else np.flatnonzero(iface == k)
        if not 0 <= k < len(ifaces):
            count = rec.shape[0] if len(kinds) == 1 else len(sel)
            ctx.problems.add(ctx.source, "packets", f"{count} packets of undeclared interface {k}")
            continue
        i = ifaces[k]
        if i.link not in (LINKTYPE_CAN_SOCKETCAN, LINKTYPE_LINUX_SLL, LINKTYPE_LINUX_SLL2):
            warned.add(i.link)  # another interface of the capture (an error if it has no CAN)
            continue
        chan = frames.channel(i.name)
        index = None if len(kinds) == 1 else sel
        fb = frames.batch(rows[sel], caplen[sel], ticks[sel] * i.tsres, i.link, chan, index)
        if fb is not None:
            parts.append(fb)
    if len(parts) > 1:  # several interfaces in one run: back in file order
        joined = concat(parts)
        parts = [joined.take(np.argsort(joined.line, kind="stable"))]
    frames.record += rec.shape[0]
    for fb in parts:
        cutter.add(fb)
        ctx.frames += len(fb)


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    echoes = EchoFilter()  # a Linux cooked capture's outgoing frames, seen again as echoes
    for fb in _read(stream, ctx):
        kept = echoes.apply(fb)
        ctx.frames -= len(fb) - len(kept)
        if len(kept):
            yield kept
    if echoes.dropped:
        ctx.extras["echoes"] = echoes.dropped
        ctx.problems.note(
            ctx.source,
            f"{echoes.dropped:,} loop-back echoes of frames this host sent left out (each "
            "appears going out and again as received: one frame, marked sent)",
        )


def _read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    head = stream.read(24)
    if head[:4] in _PCAP_MAGIC:
        yield from _read_pcap(stream, ctx, head)
        return
    # pcapng: the bytes read belong to the first block
    yield from _read_pcapng(_Prefixed(head, stream), ctx)


class _Prefixed:
    """A stream with bytes already read put back in front."""

    def __init__(self, head: bytes, stream: BinaryIO) -> None:
        self.head = head
        self.stream = stream

    def read(self, size: int = -1) -> bytes:
        head, self.head = self.head, b""
        return head + self.stream.read(size - len(head) if size >= 0 else -1)


FORMAT = register(
    LogFormat(
        name="pcap",
        description="Wireshark/tcpdump pcap or pcapng of SocketCAN (link type 227, Linux cooked)",
        sniff=sniff,
        read=read,
        suffixes=(".pcap", ".pcapng", ".cap"),
        priority=12,
        text=False,
    )
)
