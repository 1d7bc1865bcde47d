"""An unconfigured device (no node-ID) that an LSS master (CiA 305) configures.

It answers switch state selective, configure node-ID and store configuration on
0x7E4; switched back to waiting with a node-ID configured, it boots as a SimNode with
that node-ID (CiA 305: an unconfigured slave starts its NMT initialisation then).
"""

from __future__ import annotations

import random
import struct

from cananalyze.devices.profile import DeviceProfile
from cananalyze.protocol import lss
from cananalyze.sim.engine import Simulation
from cananalyze.sim.node import SDO_DELAY, SimNode

UNCONFIGURED = 0xFF  # CiA 305's node-ID of a slave that has none


class LssSlave:
    """Until configured, only LSS; then `node` is the SimNode it became (on the bus)."""

    def __init__(self, profile: DeviceProfile, serial: int, rng: random.Random):
        self.profile, self.rng = profile, rng
        revision = 0  # the profiles' 0x1018:03 default
        self.identity = (profile.vendor_id or 0, profile.product_code or 0, revision, serial)
        self.selective: list[int | None] = [None] * 4
        self.configuring = False
        self.node_id = UNCONFIGURED
        self.node: SimNode | None = None
        self.sim: Simulation | None = None

    def start(self, sim: Simulation) -> None:
        self.sim = sim

    def _answer(self, cs: int, *payload: int) -> None:
        data = bytes([cs, *payload]).ljust(8, b"\x00")
        self.sim.after(SDO_DELAY, lambda: self.sim.send(self, lss.SLAVE_COB, data))

    def on_frame(self, cob: int, data: bytes, flags: int) -> None:
        if cob != lss.MASTER_COB or not data or self.node is not None:
            return
        cs, value = data[0], struct.unpack_from("<I", bytes(data).ljust(8, b"\x00"), 1)[0]
        if cs in lss.SELECTIVE:
            part = lss.SELECTIVE.index(cs)
            self.selective[part] = value
            if part == 3:
                if tuple(self.selective) == self.identity:
                    self.configuring = True
                    self._answer(lss.CODES["switch state selective: response"])
                self.selective = [None] * 4
        elif cs == lss.CODES["switch state global"]:
            mode = data[1] if len(data) > 1 else None
            if mode == lss.WAITING and self.configuring and self.node_id != UNCONFIGURED:
                self._boot()
            self.configuring = mode == lss.CONFIGURATION
        elif not self.configuring:
            return
        elif cs == lss.CODES["configure node-ID"]:
            ok = len(data) > 1 and 1 <= data[1] <= 127
            if ok:
                self.node_id = data[1]
            self._answer(cs, 0 if ok else 1, 0)
        elif cs == lss.CODES["store configuration"]:
            self._answer(cs, 0, 0)

    def _boot(self) -> None:
        serial = self.identity[3]
        node = SimNode(self.node_id, self.profile, self.rng, config=[(0x1018, 4, serial)])
        self.node = self.sim.add(node)
        node.start(self.sim)
