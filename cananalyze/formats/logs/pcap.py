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
            rec = _run(buf, pos, count, size)
            dt = order + "u4"
            t = _col(rec, 0, dt).astype(np.float64) + _col(rec, 4, dt) * unit
            fb = frames.batch(rec[:, 16:], np.full(count, incl), t, link, chan0)
            frames.record += count
            if fb is not None:
                cutter.add(fb)
                ctx.frames += len(fb)
            pos += count * size
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
                _epb_run(
                    _run(buf, pos, count, size), order, ifaces, frames, cutter, ctx, warned_link
                )
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
    if rest:
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
