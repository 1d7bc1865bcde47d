"""EmcyDecoder: what the manufacturer meant by an EMCY's vendor bytes, from the node's profile.

EMCY frames are rare, so this walks them row by row and adds a
`manufacturer_decoded` note where the node's profile has a table for them.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.decode.model import NetworkModel
from cananalyze.protocol.emcy import MIN_BYTES
from cananalyze.protocol.services import Service


def _has_emcy_table(profile) -> bool:
    """Whether `profile.decode_emcy` can answer (a DeviceProfile needs a sidecar table)."""
    if profile is None:
        return False
    if not hasattr(profile, "sidecar"):
        return True
    return profile.sidecar is not None and profile.sidecar.emcy is not None


class EmcyDecoder:
    def __init__(self, model: NetworkModel) -> None:
        self.model = model

    def process(self, batch: DecodedBatch) -> None:
        # only nodes whose profile has a table for the vendor bytes (most have none)
        nodes = [n for n, cfg in self.model.nodes.items() if _has_emcy_table(cfg.profile)]
        if not nodes:
            return
        fb = batch.frames
        emcy = (batch.service == Service.EMCY) & np.isin(batch.node, nodes)
        for i in np.flatnonzero(emcy).tolist():
            cfg = self.model.nodes.get(int(batch.node[i]))
            if cfg is None or cfg.profile is None or fb.dlc[i] < MIN_BYTES:
                continue
            data = fb.payload(i)
            got = cfg.profile.decode_emcy(data[0] | data[1] << 8, data[2], data[3:8])
            if got is not None:
                batch.notes.setdefault(i, {})["manufacturer_decoded"] = got

    def finish(self, batch: DecodedBatch) -> None:
        pass
