"""A CiA 402 drive and its master, both python-canopen, on one virtual bus.

The master is python-canopen's own CiA 402 model (`canopen.profiles.p402.BaseNode402`),
which walks the state machine by writing controlwords and reading statuswords. The drive
is a `canopen.LocalNode` of a real drive's EDS whose statusword follows each controlword
by python-canopen's transition table (`State402.TRANSITIONTABLE`) and mask table
(`State402.SW_MASK`): the drive's behaviour is python-canopen's, not ours.
"""

from __future__ import annotations

import can
import canopen
from canopen.profiles.p402 import BaseNode402, State402

# one statusword per state: the value bits of python-canopen's masks, plus "remote"
STATUSWORD = {state: value | 0x0200 for state, (_, value) in State402.SW_MASK.items()}


class Drive402:
    def __init__(self, eds: str, node_id: int, channel: str, refuse: set[str] = frozenset()):
        self.recorder = can.Bus(interface="virtual", channel=channel)
        self.master_net, self.drive_net = canopen.Network(), canopen.Network()
        self.master_net.connect(interface="virtual", channel=channel)
        self.drive_net.connect(interface="virtual", channel=channel)
        self.drive = canopen.LocalNode(node_id, eds)
        self.drive_net.add_node(self.drive)
        self.master = BaseNode402(node_id, eds)
        self.master_net.add_node(self.master)
        self.refuse = set(refuse)  # target states this drive will not enter
        self.state = "SWITCH ON DISABLED"
        self._set(self.state)
        self.drive.add_write_callback(self._on_write)

    def _set(self, state: str) -> None:
        self.state = state
        self.drive.sdo[0x6041].raw = STATUSWORD[state]

    def _on_write(self, index, subindex, od, data) -> None:
        if index != 0x6040:
            return
        word = int.from_bytes(data, "little")
        for (src, dst), command in State402.TRANSITIONTABLE.items():
            if src == self.state and command == word and dst not in self.refuse:
                self._set(dst)
                return

    def fault(self, code: int) -> None:
        """The drive detects a fault: EMCY, then fault reaction active, then fault."""
        self.drive.emcy.send(code, 0x01)
        self._set("FAULT REACTION ACTIVE")
        self._set("FAULT")

    def frames(self) -> list[tuple[float, int, bytes]]:
        out = []
        while (msg := self.recorder.recv(0.05)) is not None:
            out.append((msg.timestamp, msg.arbitration_id, bytes(msg.data)))
        return out

    def close(self) -> None:
        self.master_net.disconnect()
        self.drive_net.disconnect()
        self.recorder.shutdown()
