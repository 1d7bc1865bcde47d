"""Which nodes sent a frame themselves: the services a node sends (heartbeat, boot-up,
TPDO, EMCY, SDO response, guard response), as opposed to those sent to it (NMT, RPDO,
SDO request). The boot-up rule, the SDO scan and the NMT state list ask it."""

from __future__ import annotations

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.protocol.services import Service

SENT_BY_NODE = np.array(
    [
        Service.HEARTBEAT,
        Service.TPDO,
        Service.EMCY,
        Service.SDO_RESPONSE,
        Service.GUARD_RESPONSE,
        Service.BOOTUP,
    ],
    np.uint8,
)
SENT = np.zeros(256, bool)  # service -> sent by the node itself: a lookup, not np.isin
SENT[SENT_BY_NODE] = True


def senders(batch: DecodedBatch) -> np.ndarray:
    """Nodes (0..127) with a row of a service the node sends itself: read from the batch's
    counts per (service, node) (`DecodedBatch.sender_counts`), not a gather of the rows."""
    per = batch.sender_counts()
    if per is None:  # a node past 127
        return np.unique(batch.node[SENT[batch.service] & (batch.node >= 0)])
    return np.flatnonzero(per[SENT, 1:].any(axis=0))
