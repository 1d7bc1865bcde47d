"""SDO server of a simulated node: every CiA 301 transfer, frame in, frames out.

Hand-written because canopen's SdoServer is bound to a live Network and its
clock, while the simulator must also run on a discrete-event clock; this one
only maps request bytes to response bytes, so both modes share it. Covers
expedited, segmented and block transfers (with CRC and the protocol switch
threshold) in both directions, and answers bad requests with abort codes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from cananalyze.protocol import sdo
from cananalyze.protocol.crc import crc16
from cananalyze.protocol.sdo import (
    ABORT_BLOCK_SIZE,
    ABORT_COMMAND,
    ABORT_CRC,
    ABORT_SEQUENCE,
    ABORT_TOGGLE,
    block_byte,
    initiate_byte,
    segment_byte,
)
from cananalyze.sim.dictionary import Dictionary, SdoAbort

BLOCK_SIZE = sdo.MAX_BLKSIZE  # segments per block the server accepts in block downloads


def abort_frame(index: int, subindex: int, code: int) -> bytes:
    return struct.pack("<BHBI", sdo.ABORT, index, subindex, code)


@dataclass
class _Transfer:
    kind: str  # "up", "down", "block_up", "block_down"
    index: int
    subindex: int
    data: bytearray = field(default_factory=bytearray)
    size: int | None = None
    toggle: int = 0
    pos: int = 0  # upload: bytes sent and acknowledged
    crc: bool = False
    blksize: int = 0
    seq: int = 0  # block download: last good sequence number
    sent: list[bytes] = field(default_factory=list)  # block upload: segments of the current block
    done: bool = False  # block: last segment sent / received


class SdoServer:
    """Request bytes -> response bytes over a Dictionary; one transfer at a time."""

    def __init__(self, od: Dictionary):
        self.od = od
        self.t: _Transfer | None = None
        self.abort_codes: dict[tuple[int, int], int] = {}  # fault injection: forced aborts

    def handle(self, req: bytes) -> list[bytes]:
        req = bytes(req).ljust(8, b"\x00")
        t = self.t
        try:
            if t is not None and t.kind == "block_down" and not t.done and req[0] != sdo.ABORT:
                return self._block_down_segment(req)
            ccs = sdo.command_specifier(req[0])
            if ccs == sdo.CS_ABORT:  # abort from the client: drop the transfer silently
                self.t = None
                return []
            if ccs == sdo.CCS_INITIATE_DOWNLOAD:
                return self._init_download(req)
            if ccs == sdo.CCS_DOWNLOAD_SEGMENT and t is not None and t.kind == "down":
                return self._download_segment(req)
            if ccs == sdo.CCS_INITIATE_UPLOAD:
                return self._init_upload(req)
            if ccs == sdo.CCS_UPLOAD_SEGMENT and t is not None and t.kind == "up":
                return self._upload_segment(req)
            if ccs == sdo.CCS_BLOCK_UPLOAD:
                return self._block_upload(req)
            if ccs == sdo.CCS_BLOCK_DOWNLOAD:
                return self._block_download(req)
            raise SdoAbort(ABORT_COMMAND)
        except SdoAbort as exc:
            index, sub = (t.index, t.subindex) if t else struct.unpack_from("<HB", req, 1)
            initiate = (sdo.CCS_INITIATE_DOWNLOAD, sdo.CCS_INITIATE_UPLOAD)
            block = (sdo.CCS_BLOCK_UPLOAD, sdo.CCS_BLOCK_DOWNLOAD)
            if ccs in initiate or (
                ccs in block and sdo.block_subcommand(req[0]) == sdo.BLOCK_INITIATE
            ):
                index, sub = struct.unpack_from("<HB", req, 1)
            self.t = None
            return [abort_frame(index, sub, exc.code)]

    def _forced(self, index: int, sub: int) -> None:
        code = self.abort_codes.get((index, sub))
        if code is not None:
            raise SdoAbort(code)

    # --- download (client writes) ---------------------------------------------------
    def _init_download(self, req: bytes) -> list[bytes]:
        index, sub = struct.unpack_from("<HB", req, 1)
        self._forced(index, sub)
        mux = req[1:4]
        if req[0] & sdo.EXPEDITED:
            self.od.write(index, sub, req[4 : 4 + sdo.expedited_size(req[0])])
            self.t = None
        else:
            self.od.check_write(index, sub)
            sized = req[0] & sdo.SIZE_INDICATED
            self.t = _Transfer(
                "down", index, sub, size=struct.unpack_from("<I", req, 4)[0] if sized else None
            )
        return [bytes([sdo.INITIATE_DOWNLOAD_RESPONSE]) + mux + b"\x00" * 4]

    def _download_segment(self, req: bytes) -> list[bytes]:
        t = self.t
        toggle = int(bool(req[0] & sdo.TOGGLE))
        if toggle != t.toggle:
            raise SdoAbort(ABORT_TOGGLE)
        n = sdo.SEGMENT_SIZE - sdo.segment_unused(req[0])
        t.data += req[1 : 1 + n]
        t.toggle ^= 1
        if req[0] & sdo.LAST_SEGMENT:
            self.t = None
            self.od.write(t.index, t.subindex, bytes(t.data))
        return [bytes([segment_byte(sdo.SCS_DOWNLOAD_SEGMENT, toggle)]) + b"\x00" * 7]

    # --- upload (client reads) -------------------------------------------------------
    def _init_upload(self, req: bytes) -> list[bytes]:
        index, sub = struct.unpack_from("<HB", req, 1)
        self._forced(index, sub)
        data = self.od.read(index, sub)
        return self._upload_start(index, sub, data)

    def _upload_start(self, index: int, sub: int, data: bytes) -> list[bytes]:
        mux = struct.pack("<HB", index, sub)
        if 0 < len(data) <= sdo.EXPEDITED_SIZE:
            self.t = None
            head = initiate_byte(sdo.SCS_INITIATE_UPLOAD, len(data), expedited=True)
            return [bytes([head]) + mux + data.ljust(4, b"\x00")]
        self.t = _Transfer("up", index, sub, data=bytearray(data))
        head = initiate_byte(sdo.SCS_INITIATE_UPLOAD, len(data))
        return [bytes([head]) + mux + struct.pack("<I", len(data))]

    def _upload_segment(self, req: bytes) -> list[bytes]:
        t = self.t
        toggle = int(bool(req[0] & sdo.TOGGLE))
        if toggle != t.toggle:
            raise SdoAbort(ABORT_TOGGLE)
        chunk = bytes(t.data[t.pos : t.pos + sdo.SEGMENT_SIZE])
        t.pos += len(chunk)
        t.toggle ^= 1
        last = t.pos >= len(t.data)
        if last:
            self.t = None
        head = segment_byte(sdo.SCS_UPLOAD_SEGMENT, toggle, sdo.SEGMENT_SIZE - len(chunk), last)
        return [bytes([head]) + chunk.ljust(sdo.SEGMENT_SIZE, b"\x00")]

    # --- block upload ------------------------------------------------------------------
    def _block_upload(self, req: bytes) -> list[bytes]:
        cs = sdo.block_subcommand(req[0])
        t = self.t
        if cs == sdo.BLOCK_INITIATE:
            index, sub = struct.unpack_from("<HB", req, 1)
            self._forced(index, sub)
            data = self.od.read(index, sub)
            blksize, pst = req[4], req[5]
            if not 0 < blksize <= sdo.MAX_BLKSIZE:
                raise SdoAbort(ABORT_BLOCK_SIZE)
            if pst and len(data) <= pst:  # protocol switch: answer as a normal upload
                return self._upload_start(index, sub, data)
            crc = bool(req[0] & sdo.CRC_SUPPORTED)
            self.t = _Transfer(
                "block_up", index, sub, data=bytearray(data), crc=crc, blksize=blksize
            )
            head = block_byte(sdo.SCS_BLOCK_UPLOAD, sdo.BLOCK_INITIATE, crc=True, sized=True)
            return [bytes([head]) + struct.pack("<HBI", index, sub, len(data))]
        if cs == sdo.BLOCK_END and t is not None and t.kind == "block_up_end":  # end confirmed
            self.t = None
            return []
        if t is None or t.kind != "block_up":
            raise SdoAbort(ABORT_COMMAND)
        if cs == sdo.BLOCK_START:
            return self._next_block()
        if cs == sdo.BLOCK_ACK:
            ackseq, blksize = req[1], req[2]
            if not 0 < blksize <= sdo.MAX_BLKSIZE:
                raise SdoAbort(ABORT_BLOCK_SIZE)
            if ackseq > len(t.sent):
                raise SdoAbort(ABORT_SEQUENCE)
            t.pos += sum(len(s) for s in t.sent[:ackseq])
            t.blksize = blksize
            if ackseq < len(t.sent):
                t.done = False
            if t.done or t.pos >= len(t.data):
                size = sdo.SEGMENT_SIZE
                last = len(t.data) % size or (size if t.data else 0)
                crc = crc16(bytes(t.data)) if t.crc else 0
                t.kind = "block_up_end"
                head = block_byte(sdo.SCS_BLOCK_UPLOAD, sdo.BLOCK_END, unused=size - last)
                return [bytes([head]) + struct.pack("<H", crc) + b"\x00" * 5]
            return self._next_block()
        raise SdoAbort(ABORT_COMMAND)

    def _next_block(self) -> list[bytes]:
        t = self.t
        t.sent = []
        frames = []
        pos = t.pos
        for seq in range(1, t.blksize + 1):
            chunk = bytes(t.data[pos : pos + sdo.SEGMENT_SIZE])
            pos += len(chunk)
            last = pos >= len(t.data)
            t.sent.append(chunk)
            head = seq | (sdo.NO_MORE_SEGMENTS if last else 0)
            frames.append(bytes([head]) + chunk.ljust(sdo.SEGMENT_SIZE, b"\x00"))
            if last:
                t.done = True
                break
        return frames

    # --- block download ------------------------------------------------------------------
    def _block_download(self, req: bytes) -> list[bytes]:
        cs = sdo.block_subcommand(req[0], one_bit=True)
        t = self.t
        if cs == sdo.BLOCK_INITIATE:
            index, sub = struct.unpack_from("<HB", req, 1)
            self._forced(index, sub)
            self.od.check_write(index, sub)
            sized = req[0] & sdo.BLOCK_SIZE_INDICATED
            size = struct.unpack_from("<I", req, 4)[0] if sized else None
            crc = bool(req[0] & sdo.CRC_SUPPORTED)
            self.t = _Transfer("block_down", index, sub, size=size, crc=crc, blksize=BLOCK_SIZE)
            head = block_byte(sdo.SCS_BLOCK_DOWNLOAD, sdo.BLOCK_INITIATE, crc=True)
            return [bytes([head]) + struct.pack("<HBB", index, sub, BLOCK_SIZE) + b"\x00" * 3]
        if t is None or t.kind != "block_down" or not t.done:
            raise SdoAbort(ABORT_COMMAND)
        unused = sdo.block_end_unused(req[0])  # end: bytes of the last segment without data
        if unused:
            del t.data[-unused:]
        if t.crc and struct.unpack_from("<H", req, 1)[0] != crc16(bytes(t.data)):
            raise SdoAbort(ABORT_CRC)
        self.t = None
        self.od.write(t.index, t.subindex, bytes(t.data))
        return [bytes([block_byte(sdo.SCS_BLOCK_DOWNLOAD, sdo.BLOCK_END)]) + b"\x00" * 7]

    def _block_down_segment(self, req: bytes) -> list[bytes]:
        t = self.t
        seq, last = req[0] & sdo.SEQNO_MASK, bool(req[0] & sdo.NO_MORE_SEGMENTS)
        if seq == t.seq + 1:
            t.seq = seq
            t.data += req[1:8]
            if last:
                t.done = True
        if t.done or seq >= t.blksize:
            ack = bytes([block_byte(sdo.SCS_BLOCK_DOWNLOAD, sdo.BLOCK_ACK), t.seq, BLOCK_SIZE])
            ack += b"\x00" * 5
            t.seq = 0
            return [ack]
        return []
