"""Columnar COB-ID classification by the CiA 301 predefined connection set.

A 2048-entry lookup table per column (service, node, PDO number) turns the
can_id column into services with one numpy `take`. The network model edits the
table when the log reassigns COB-IDs (PDO, SDO channel, EMCY COB-ID writes), so
remapped frames are attributed to the right node without per-frame Python.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR, FrameBatch
from cananalyze.protocol import nmt
from cananalyze.protocol.services import Service
from cananalyze.runtime import speedups

NO_NODE = -1
# the service codes the compiled classifier needs, in its order
_C_CODES = np.array(
    [
        Service.OTHER,
        Service.ERROR_FRAME,
        Service.HEARTBEAT,
        Service.BOOTUP,
        Service.GUARD_RESPONSE,
        Service.GUARD_REQUEST,
        Service.ERRCTL_INVALID,
    ],
    np.uint8,
)


@dataclass
class Classified:
    """Per-row result columns for one batch."""

    service: np.ndarray  # uint8 Service codes
    node: np.ndarray  # int16 node-ID, NO_NODE when the service has none
    pdo: np.ndarray  # uint8 PDO number (1-based), 0 when not a PDO


def default_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lookup tables of the predefined connection set for 11-bit identifiers."""
    svc = np.full(2048, Service.OTHER, np.uint8)
    node = np.full(2048, NO_NODE, np.int16)
    pdo = np.zeros(2048, np.uint8)
    svc[0x000] = Service.NMT
    svc[0x080] = Service.SYNC
    svc[0x100] = Service.TIME
    svc[0x7E4] = Service.LSS_SLAVE
    svc[0x7E5] = Service.LSS_MASTER
    ids = np.arange(1, 128)
    ranges = [
        (0x080, Service.EMCY, 0),
        (0x180, Service.TPDO, 1),
        (0x200, Service.RPDO, 1),
        (0x280, Service.TPDO, 2),
        (0x300, Service.RPDO, 2),
        (0x380, Service.TPDO, 3),
        (0x400, Service.RPDO, 3),
        (0x480, Service.TPDO, 4),
        (0x500, Service.RPDO, 4),
        (0x580, Service.SDO_RESPONSE, 0),
        (0x600, Service.SDO_REQUEST, 0),
        (0x700, Service.HEARTBEAT, 0),
    ]
    for base, service, number in ranges:
        svc[base + ids] = service
        node[base + ids] = ids
        pdo[base + ids] = number
    return svc, node, pdo


class CobClassifier:
    """Classifies batches; keeps the little state error control needs across batches.

    Error control (0x700+n) is one COB-ID for heartbeat, boot-up and guarding: a
    1-byte frame answering an RTR on the same COB-ID is a guard response; a 0x00
    byte otherwise is a boot-up; anything else a heartbeat. A data frame there of
    any other length is none of them (CiA 301: 1 byte; another protocol's traffic
    on these identifiers): `errctl_invalid`, and it leaves the RTR state alone so a
    guard request still pairs with its answer.
    """

    def __init__(self) -> None:
        self.svc, self.node, self.pdo = default_tables()
        self._prev_rtr = np.zeros(2048, bool)  # last error-control frame per COB-ID was an RTR

    # --- table edits, made by the network model when configuration changes in the log
    def assign(self, cob_id: int, service: Service, node: int, pdo: int = 0) -> None:
        if 0 <= cob_id < 2048:
            self.svc[cob_id] = service
            self.node[cob_id] = node
            self.pdo[cob_id] = pdo

    def release(self, cob_id: int) -> None:
        """Give a COB-ID back its predefined meaning."""
        if 0 <= cob_id < 2048:
            svc, node, pdo = default_tables()
            self.svc[cob_id], self.node[cob_id], self.pdo[cob_id] = (
                svc[cob_id],
                node[cob_id],
                pdo[cob_id],
            )

    def classify(self, batch: FrameBatch) -> Classified:
        """Service, node and PDO number per row.

        Only a standard frame with an identifier that fits 11 bits is looked up: a
        29-bit frame, an error frame, or a "standard" frame claiming an id above
        0x7FF (a bus cannot carry one; a corrupt or hand-made log can) is `other`
        (or `error_frame`), never a CANopen service.
        """
        fast = getattr(speedups.C, "classify", None)
        if fast is not None:
            return self._classify_c(fast, batch)
        return self._classify_numpy(batch)

    def _classify_numpy(self, batch: FrameBatch) -> Classified:
        can_id = batch.can_id
        flags = batch.flags
        std = ((flags & (FLAG_EXT | FLAG_ERR)) == 0) & (can_id <= 0x7FF)
        idx = np.where(std, can_id, 0).astype(np.intp)
        service = np.where(std, self.svc[idx], Service.OTHER).astype(np.uint8)
        service[(flags & FLAG_ERR) != 0] = Service.ERROR_FRAME
        node = np.where(std, self.node[idx], NO_NODE).astype(np.int16)
        pdo = np.where(std, self.pdo[idx], 0).astype(np.uint8)
        self._refine_error_control(batch, service)
        return Classified(service, node, pdo)

    def _classify_c(self, fast, batch: FrameBatch) -> Classified:
        """The same columns in one compiled pass, GIL released: 0.04 s per 10M frames
        against numpy's 0.19 s, a twentieth of `check`'s main thread (measured)."""
        n = len(batch)
        service = np.empty(n, np.uint8)
        node = np.empty(n, np.int16)
        pdo = np.empty(n, np.uint8)
        c = np.ascontiguousarray
        fast(
            c(batch.can_id, np.uint32),
            c(batch.flags, np.uint8),
            c(batch.dlc, np.uint8),
            c(batch.data, np.uint8),
            self.svc,
            self.node,
            self.pdo,
            self._prev_rtr.view(np.uint8),
            _C_CODES,
            service,
            node,
            pdo,
        )
        return Classified(service, node, pdo)

    def _refine_error_control(self, batch: FrameBatch, service: np.ndarray) -> None:
        rows = np.flatnonzero(service == Service.HEARTBEAT)
        if rows.size == 0:
            return
        rtr = (batch.flags[rows] & FLAG_RTR) != 0
        invalid = ~rtr & (batch.dlc[rows] != 1)
        if invalid.any():
            service[rows[invalid]] = Service.ERRCTL_INVALID
            rows, rtr = rows[~invalid], rtr[~invalid]
        ids = batch.can_id[rows].astype(np.intp)
        # previous error-control frame on the same COB-ID: within the batch by a stable
        # sort on COB-ID, across batches from the carried state.
        order = np.argsort(ids, kind="stable")
        sid, srtr = ids[order], rtr[order]
        prev_rtr = np.empty_like(srtr)
        prev_rtr[1:] = srtr[:-1]
        first = np.ones(sid.size, bool)
        first[1:] = sid[1:] != sid[:-1]
        prev_rtr[first] = self._prev_rtr[sid[first]]
        last = np.ones(sid.size, bool)
        last[:-1] = sid[1:] != sid[:-1]
        self._prev_rtr[sid[last]] = srtr[last]
        after_rtr = np.empty_like(prev_rtr)
        after_rtr[order] = prev_rtr
        byte0 = batch.data[rows, 0]  # every data frame left has its 1 byte
        out = np.full(rows.size, Service.HEARTBEAT, np.uint8)
        out[~rtr & (byte0 == nmt.BOOTUP)] = Service.BOOTUP
        state = byte0 & nmt.STATE_MASK
        out[after_rtr & ~rtr & (state != nmt.BOOTUP)] = Service.GUARD_RESPONSE
        out[rtr] = Service.GUARD_REQUEST
        service[rows] = out
