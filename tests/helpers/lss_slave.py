"""A CiA 305 LSS slave on a python-can bus, for python-canopen's LssMaster to talk to.

python-canopen has the master side only; this is the device: waiting / configuration
state, switch state global and selective, fastscan (CiA 305's bitChecked / lssSub /
lssNext walk), configure node-ID (1..127 and 255, else error 1), store, inquire node-ID.
It answers from the bus's notifier thread, at once.
"""

from __future__ import annotations

import struct

import can

MASTER, SLAVE = 0x7E5, 0x7E4


class LssSlave(can.Listener):
    def __init__(self, bus: can.BusABC, identity: tuple[int, int, int, int]) -> None:
        self.bus, self.identity = bus, identity
        self.node_id = 0xFF  # not configured
        self.pending_id = 0xFF
        self.configuration = False
        self.selective: list[int | None] = [None] * 4
        self.lss_pos = 0
        self.stored = False

    def _send(self, *data: int) -> None:
        self.bus.send(
            can.Message(
                arbitration_id=SLAVE, data=bytes(data).ljust(8, b"\0"), is_extended_id=False
            )
        )

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id != MASTER or not msg.data:
            return
        d = bytes(msg.data)
        cs = d[0]
        if cs == 0x04:
            self.configuration = d[1] == 1
            if not self.configuration and self.pending_id != self.node_id:
                self.node_id = self.pending_id  # the new node-ID takes effect
        elif 0x40 <= cs <= 0x43:
            self.selective[cs - 0x40] = struct.unpack_from("<I", d, 1)[0]
            if cs == 0x43:
                if tuple(self.selective) == self.identity:
                    self.configuration = True
                    self._send(0x44)
                self.selective = [None] * 4
        elif cs == 0x51:
            number, bit, sub, nxt = struct.unpack_from("<IBBB", d, 1)
            if bit == 0x80:
                if self.node_id == 0xFF and not self.configuration:
                    self.lss_pos = 0
                    self._send(0x4F)
                return
            if self.node_id != 0xFF or self.configuration or sub != self.lss_pos:
                return
            if (self.identity[sub] ^ number) >> bit == 0:
                self._send(0x4F)
                if bit == 0:  # CANopenNode's CO_LSSslave: the walk moves on, or ends
                    if nxt < sub:
                        self.configuration = True
                    self.lss_pos = nxt
        elif not self.configuration:
            return
        elif cs == 0x11:
            if 1 <= d[1] <= 127 or d[1] == 0xFF:
                self.pending_id = d[1]
                self._send(0x11, 0)
            else:
                self._send(0x11, 1)
        elif cs == 0x17:
            self.stored = True
            self._send(0x17, 0)
        elif cs == 0x5E:
            self._send(0x5E, self.node_id)
