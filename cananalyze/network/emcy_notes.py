"""EmcyDecoder: what the manufacturer meant by an EMCY's vendor bytes, from the node's profile.

EMCY frames are rare, so this walks them row by row and adds a
`manufacturer_decoded` note where the node's profile has a table for them.
"""

from __future__ import annotations

import numpy as np

from cananalyze.decoded import DecodedBatch
from cananalyze.network.model import NetworkModel
from cananalyze.protocol.services import Service


class EmcyDecoder:
    def __init__(self, model: NetworkModel) -> None:
        self.model = model

    def process(self, batch: DecodedBatch) -> None:
        if not any(cfg.profile is not None for cfg in self.model.nodes.values()):
            return
        fb = batch.frames
        for i in np.flatnonzero(batch.service == Service.EMCY).tolist():
            cfg = self.model.nodes.get(int(batch.node[i]))
            if cfg is None or cfg.profile is None or fb.dlc[i] < 3:
                continue
            data = fb.payload(i)
            got = cfg.profile.decode_emcy(data[0] | data[1] << 8, data[2], data[3:8])
            if got is not None:
                batch.notes.setdefault(i, {})["manufacturer_decoded"] = got

    def finish(self, batch: DecodedBatch) -> None:
        pass
