"""A CiA 301 SDO server for block transfers, on a python-can bus, for tests.

`canopen`'s own server has no block mode (it answers a block upload with a normal
one), so the block client of `canopen` needs this to talk to. Implements block
upload (with the protocol switch threshold: small objects fall back to an
expedited or segmented upload, as CiA 301 allows) and block download, CRC-16 when
the client asks, and a configurable blksize sequence for download sub-blocks.
"""

from __future__ import annotations

import binascii
import struct

import can


class BlockSdoServer(can.Listener):
    def __init__(
        self,
        bus: can.BusABC,
        node: int,
        objects: dict[tuple[int, int], bytes],
        blksizes: tuple[int, ...] = (127,),
        crc: bool = True,
    ) -> None:
        self.bus = bus
        self.node = node
        self.objects = objects
        self.blksizes = blksizes  # download: blksize for sub-block 1, 2, ... (last repeats)
        self.crc = crc
        self._state: dict = {}

    # -- plumbing ---------------------------------------------------------------

    def _send(self, payload: bytes) -> None:
        frame = bytes(payload).ljust(8, b"\x00")
        self.bus.send(
            can.Message(arbitration_id=0x580 + self.node, data=frame, is_extended_id=False)
        )

    def _abort(self, index: int, subindex: int, code: int) -> None:
        self._state = {}
        self._send(struct.pack("<BHBI", 0x80, index, subindex, code))

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id != 0x600 + self.node or msg.is_remote_frame:
            return
        data = bytes(msg.data)
        st = self._state
        if st.get("phase") == "download_segments":
            self._download_segment(data)
            return
        ccs = data[0] >> 5
        if ccs == 5:
            self._block_upload(data)
        elif ccs == 6:
            self._block_download(data)
        elif ccs == 3 and st.get("phase") == "segmented":
            self._segmented_upload(data)
        elif ccs == 4:
            self._state = {}
        else:
            self._abort(*struct.unpack_from("<HB", data, 1), 0x05040001)

    # -- block upload -----------------------------------------------------------

    def _block_upload(self, data: bytes) -> None:
        st = self._state
        cs = data[0] & 0x03
        if cs == 0:  # initiate
            index, subindex, blksize, pst = struct.unpack_from("<HBBB", data, 1)
            value = self.objects.get((index, subindex))
            if value is None:
                self._abort(index, subindex, 0x06020000)
                return
            if pst and len(value) <= pst:
                self._switch_to_normal_upload(index, subindex, value)
                return
            self._state = {
                "phase": "upload_start",
                "mux": (index, subindex),
                "value": value,
                "offset": 0,
                "blksize": blksize,
                "crc": self.crc and bool(data[0] & 0x04),
            }
            cmd = 0xC2 | (0x04 if self._state["crc"] else 0)
            self._send(struct.pack("<BHBI", cmd, index, subindex, len(value)))
        elif cs == 3 and st.get("phase") == "upload_start":
            self._send_sub_block()
        elif cs == 2 and st.get("phase") == "upload_ack":
            ackseq, blksize = data[1], data[2]
            st["offset"] = st["block_start"] + 7 * ackseq
            st["blksize"] = blksize
            if st["offset"] >= len(st["value"]):
                value = st["value"]
                n = (7 - len(value) % 7) % 7
                crc = binascii.crc_hqx(value, 0) if st["crc"] else 0
                st["phase"] = "upload_end"
                self._send(struct.pack("<BH", 0xC1 | n << 2, crc))
            else:
                self._send_sub_block()
        elif cs == 1 and st.get("phase") == "upload_end":
            self._state = {}

    def _send_sub_block(self) -> None:
        st = self._state
        value, offset = st["value"], st["offset"]
        st["block_start"] = offset
        for seqno in range(1, st["blksize"] + 1):
            chunk = value[offset : offset + 7]
            offset += 7
            last = offset >= len(value)
            self._send(bytes([seqno | (0x80 if last else 0)]) + chunk)
            if last:
                break
        st["phase"] = "upload_ack"

    def _switch_to_normal_upload(self, index: int, subindex: int, value: bytes) -> None:
        if len(value) <= 4:
            cmd = 0x43 | (4 - len(value)) << 2
            self._send(struct.pack("<BHB", cmd, index, subindex) + value)
            self._state = {}
            return
        self._state = {"phase": "segmented", "value": value, "offset": 0, "toggle": 0}
        self._send(struct.pack("<BHBI", 0x41, index, subindex, len(value)))

    def _segmented_upload(self, data: bytes) -> None:
        st = self._state
        toggle = (data[0] >> 4) & 1
        chunk = st["value"][st["offset"] : st["offset"] + 7]
        st["offset"] += 7
        last = st["offset"] >= len(st["value"])
        cmd = toggle << 4 | (7 - len(chunk)) << 1 | (1 if last else 0)
        self._send(bytes([cmd]) + chunk)
        if last:
            self._state = {}

    # -- block download ---------------------------------------------------------

    def _block_download(self, data: bytes) -> None:
        st = self._state
        if data[0] & 0x01 == 0:  # initiate
            index, subindex = struct.unpack_from("<HB", data, 1)
            self._state = {
                "phase": "download_segments",
                "mux": (index, subindex),
                "received": bytearray(),
                "block": [],
                "sub_block": 0,
                "crc": self.crc and bool(data[0] & 0x04),
            }
            blksize = self._next_blksize()
            cmd = 0xA0 | (0x04 if self._state["crc"] else 0)
            self._send(struct.pack("<BHBB", cmd, index, subindex, blksize))
        elif st.get("phase") == "download_end":
            n = (data[0] >> 2) & 0x07
            crc = struct.unpack_from("<H", data, 1)[0]
            value = bytes(st["received"][: len(st["received"]) - n])
            if st["crc"] and binascii.crc_hqx(value, 0) != crc:
                self._abort(*st["mux"], 0x05040004)
                return
            self.objects[st["mux"]] = value
            self._state = {}
            self._send(b"\xa1")

    def _next_blksize(self) -> int:
        st = self._state
        size = self.blksizes[min(st["sub_block"], len(self.blksizes) - 1)]
        st["sub_block"] += 1
        st["blksize"] = size
        return size

    def _download_segment(self, data: bytes) -> None:
        st = self._state
        if data[0] == 0x80:  # abort from the client
            self._state = {}
            return
        seqno, last = data[0] & 0x7F, bool(data[0] & 0x80)
        if seqno == len(st["block"]) + 1:
            st["block"].append(data[1:8])
        if last or seqno >= st["blksize"]:
            ackseq = len(st["block"])
            for segment in st["block"]:
                st["received"] += segment
            st["block"] = []
            st["phase"] = "download_end" if last else "download_segments"
            self._send(bytes([0xA2, ackseq, self._next_blksize()]))
