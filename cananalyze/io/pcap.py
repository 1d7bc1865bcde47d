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
record over MAX_RECORD or its snap length, a pcapng block over MAX_BLOCK, ends
the read with one problem naming the offset; what came before is kept.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from ..errors import InputError
from ..frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
)
from .blf import _Cutter
from .registry import LogFormat, ReadContext, register

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

_PCAP_MAGIC = {
    b"\xd4\xc3\xb2\xa1": ("<", 1e-6),
    b"\xa1\xb2\xc3\xd4": (">", 1e-6),
    b"\x4d\x3c\xb2\xa1": ("<", 1e-9),
    b"\xa1\xb2\x3c\x4d": (">", 1e-9),
}
_SHB = 0x0A0D0D0A
_IDB, _EPB, _SPB, _OPB = 1, 6, 3, 2


def sniff(head: bytes) -> bool:
    return head[:4] in _PCAP_MAGIC or (
        head[:4] == b"\x0a\x0d\x0d\x0a" and head[8:12] in (b"\x4d\x3c\x2b\x1a", b"\x1a\x2b\x3c\x4d")
    )


class _Frames:
    """The CAN frames of packets whose bytes are in `buf`, as FrameBatch columns."""

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
        buf: np.ndarray,
        at: np.ndarray,  # offset of each packet's data
        caplen: np.ndarray,
        t: np.ndarray,
        link: int,
        channel: np.ndarray,
    ) -> FrameBatch | None:
        n = at.size
        first = self.record
        self.record += n
        if n == 0:
            return None
        at = at.astype(np.int64)
        caplen = caplen.astype(np.int64)
        tx = np.zeros(n, bool)
        big = link == LINKTYPE_CAN_SOCKETCAN
        if link in (LINKTYPE_LINUX_SLL, LINKTYPE_LINUX_SLL2):
            hdr = 16 if link == LINKTYPE_LINUX_SLL else 20
            ok = caplen >= hdr
            pos = np.where(ok, at, 0)
            p_at = pos + (14 if link == LINKTYPE_LINUX_SLL else 0)
            proto = (buf[p_at].astype(np.int64) << 8) | buf[p_at + 1]
            kind_at = pos + (1 if link == LINKTYPE_LINUX_SLL else 10)
            tx = buf[kind_at] == PACKET_OUTGOING
            ok &= (proto == ETH_P_CAN) | (proto == ETH_P_CANFD)
            self.not_can += int(np.count_nonzero(~ok))
            at, caplen, tx = at + hdr, caplen - hdr, tx
            keep = np.flatnonzero(ok)
        else:
            keep = np.arange(n)
        whole = caplen[keep] >= 8
        self.cut += int(np.count_nonzero(~whole))
        keep = keep[whole]
        h = at[keep]
        cl = caplen[keep]
        m = keep.size
        word = np.zeros(m, np.uint32)
        for k in range(4):  # the identifier word, network or host byte order
            shift = 8 * (3 - k) if big else 8 * k
            word |= buf[h + k].astype(np.uint32) << np.uint32(shift)
        length = buf[h + 4].astype(np.int64)
        fdflags = buf[h + 5]
        fd = (fdflags & 0x04).astype(bool) | (cl >= 72) | (length > 8)
        length = np.minimum(length, np.where(fd, 64, 8))
        short = cl < 8 + length
        self.cut += int(np.count_nonzero(short))
        length = np.minimum(length, cl - 8)
        fb = FrameBatch.allocate(m)
        fb.t[:] = t[keep]
        ext = (word & 0x80000000) != 0
        err = (word & 0x20000000) != 0
        rtr = (word & 0x40000000) != 0
        flags = np.zeros(m, np.uint8)
        flags[ext & ~err] |= FLAG_EXT
        flags[err] |= FLAG_ERR
        flags[rtr & ~err] |= FLAG_RTR
        flags[fd] |= FLAG_FD
        flags[fd & ((fdflags & 0x01) != 0)] |= FLAG_BRS
        flags[fd & ((fdflags & 0x02) != 0)] |= FLAG_ESI
        flags[tx[keep]] |= FLAG_TX
        fb.flags[:] = flags
        fb.can_id[:] = np.where(ext | err, word & 0x1FFFFFFF, word & 0x7FF)
        remote = rtr & ~err
        stored = np.where(remote, 0, length)
        # a remote request's len field is the DLC it asks for (candump shows it so)
        fb.dlc[:] = np.where(remote, np.minimum(buf[h + 4], 8), length).astype(np.uint8)
        cols = np.arange(8)
        inside = cols[None, :] < np.minimum(stored, 8)[:, None]
        gather = np.where(inside, h[:, None] + 8 + cols[None, :], 0)
        fb.data[:] = np.where(inside, buf[gather], 0)
        for r in np.flatnonzero(stored > 8).tolist():
            a = int(h[r]) + 8
            fb.long_data[r] = buf[a : a + int(stored[r])].tobytes()
        fb.channel[:] = channel[keep]
        fb.line[:] = first + 1 + keep
        fb.channels = tuple(self.channels)
        return fb


def _uniform(
    buf: np.ndarray, pos: int, size: int, order: str, length_at: int, add: int, kind: int | None
) -> int:
    """How many records of `size` bytes follow each other from `pos` (at least 1): each
    one's length field (u32 at `length_at`, plus `add`) says `size`, and for pcapng its
    block type is `kind`."""
    n = (len(buf) - pos) // size
    if n <= 1:
        return 1
    offs = pos + np.arange(n, dtype=np.int64) * size
    same = _u32(buf, offs + length_at, order).astype(np.int64) + add == size
    if kind is not None:
        same &= _u32(buf, offs, order) == kind
    bad = np.flatnonzero(~same)
    return int(bad[0]) if bad.size else n


def _u32(buf: np.ndarray, offs: np.ndarray, order: str) -> np.ndarray:
    b = [buf[offs + k].astype(np.uint32) for k in range(4)]
    if order == "<":
        return b[0] | (b[1] << 8) | (b[2] << 16) | (b[3] << 24)
    return (b[0] << 24) | (b[1] << 16) | (b[2] << 8) | b[3]


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
    cutter = _Cutter(ctx.batch_size)
    rest = b""
    offset = 24  # file offset of rest[0]
    ended = False
    while not ended:
        data = stream.read(CHUNK)
        ended = not data
        raw = rest + data
        buf = np.frombuffer(raw, np.uint8)
        pos = 0
        starts: list[np.ndarray] = []
        while pos + 16 <= len(raw):
            (incl,) = struct.unpack_from(order + "I", raw, pos + 8)
            if incl > limit:
                ctx.problems.add(
                    ctx.source,
                    f"offset {offset + pos}",
                    f"pcap record of {incl} bytes is longer than its snap length {limit} "
                    "(corrupt file): rest skipped",
                )
                ended, raw = True, raw[:pos]
                break
            size = 16 + incl
            if pos + size > len(raw):
                break
            count = _uniform(buf, pos, size, order, 8, 16, None)
            starts.append(pos + np.arange(count, dtype=np.int64) * size)
            pos += count * size
        if starts:
            rec = np.concatenate(starts)
            sec = _u32(buf, rec, order).astype(np.float64)
            frac = _u32(buf, rec + 4, order).astype(np.float64)
            caplen = _u32(buf, rec + 8, order).astype(np.int64)
            chan = np.full(rec.size, chan0, np.uint16)
            fb = frames.batch(buf, rec + 16, caplen, sec + frac * unit, link, chan)
            if fb is not None:
                cutter.add(fb)
                ctx.frames += len(fb)
            yield from cutter.full()
        offset += pos
        rest = raw[pos:]
    if rest:
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
    while not ended:
        data = stream.read(CHUNK)
        ended = not data
        raw = rest + data
        buf = np.frombuffer(raw, np.uint8)
        pos = 0
        epbs: list[np.ndarray] = []
        while pos + 12 <= len(raw):
            kind = struct.unpack_from(order + "I", raw, pos)[0]
            if kind == _SHB:
                bom = raw[pos + 8 : pos + 12]
                order = "<" if bom == b"\x4d\x3c\x2b\x1a" else ">"
                if bom not in (b"\x4d\x3c\x2b\x1a", b"\x1a\x2b\x3c\x4d"):
                    ctx.problems.add(
                        ctx.source, f"offset {offset + pos}", "bad pcapng byte-order magic"
                    )
                    ended, raw = True, raw[:pos]
                    break
            size = struct.unpack_from(order + "I", raw, pos + 4)[0]
            if size < 12 or size % 4 or size > MAX_BLOCK:
                ctx.problems.add(
                    ctx.source,
                    f"offset {offset + pos}",
                    f"pcapng block of {size} bytes is impossible (corrupt file): rest skipped",
                )
                ended, raw = True, raw[:pos]
                break
            if pos + size > len(raw):
                break
            if kind == _EPB:
                count = _uniform(buf, pos, size, order, 4, 0, _EPB)
                epbs.append(pos + np.arange(count, dtype=np.int64) * size)
                pos += count * size
                continue
            if epbs:  # blocks of other kinds: the packets before them first (interface order)
                _epb_batch(
                    buf, np.concatenate(epbs), order, ifaces, frames, cutter, ctx, warned_link
                )
                epbs = []
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
        if epbs:
            _epb_batch(buf, np.concatenate(epbs), order, ifaces, frames, cutter, ctx, warned_link)
        yield from cutter.full()
        offset += pos
        rest = raw[pos:]
    if rest:
        ctx.problems.add(
            ctx.source, f"offset {offset}", f"file ends inside a pcapng block ({len(rest)} bytes)"
        )
    if warned_link and not ctx.frames:
        _other_link(ctx, min(warned_link))
    _summary(ctx, frames)
    yield from cutter.rest()


def _epb_batch(buf, blocks, order, ifaces, frames: _Frames, cutter, ctx, warned) -> None:
    iface = _u32(buf, blocks + 8, order).astype(np.int64)
    hi = _u32(buf, blocks + 12, order).astype(np.float64)
    lo = _u32(buf, blocks + 16, order).astype(np.float64)
    caplen = _u32(buf, blocks + 20, order).astype(np.int64)
    size = _u32(buf, blocks + 4, order).astype(np.int64)
    caplen = np.minimum(caplen, np.maximum(size - 32, 0))  # never past the block
    ticks = hi * 4294967296.0 + lo
    for k in np.unique(iface).tolist():
        sel = np.flatnonzero(iface == k)
        if not 0 <= k < len(ifaces):
            ctx.problems.add(
                ctx.source, "packets", f"{sel.size} packets of undeclared interface {k}"
            )
            continue
        i = ifaces[k]
        if i.link not in (LINKTYPE_CAN_SOCKETCAN, LINKTYPE_LINUX_SLL, LINKTYPE_LINUX_SLL2):
            warned.add(i.link)  # another interface of the capture (an error if it has no CAN)
            continue
        chan = np.full(sel.size, frames.channel(i.name), np.uint16)
        fb = frames.batch(buf, blocks[sel] + 28, caplen[sel], ticks[sel] * i.tsres, i.link, chan)
        if fb is not None:
            if len(np.unique(iface)) > 1:
                fb = fb.take(np.argsort(fb.t, kind="stable"))
            cutter.add(fb)
            ctx.frames += len(fb)


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
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
        priority=10,
    )
)
