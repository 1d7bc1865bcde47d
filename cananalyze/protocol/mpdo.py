"""MPDO (CiA 301 7.2.2.3, multiplexed PDO): the layout, as data, and the text.

A PDO is an MPDO when its mapping's number of entries (sub 0 of 0x1600+/0x1A00+) is 0xFE
(source address mode, SAM: the frame names its producer) or 0xFF (destination address
mode, DAM: the frame names its consumer, 0 all of them). Every MPDO frame has 8 bytes:

    byte 0     bit 7: address type (1 DAM, 0 SAM); bits 0-6: the node-ID
    bytes 1-2  the object's index (little-endian)
    byte 3     its sub-index
    bytes 4-7  its value (little-endian, as many bytes as the object has)

The reference encoding is Lely's lely-core (github.com/lely-industries/lely-core, commit
620d1858): `CO_PDO_MAP_SAM_MPDO 0xfe` and `CO_PDO_MAP_DAM_MPDO 0xff` (include/lely/co/pdo.h
lines 52 and 58); a DAM frame `data[0] = id | 0x80`, a SAM frame `data[0] = id` (the
producer's own node-ID), then the index little-endian, the sub-index and 4 bytes of value,
`len = CAN_MAX_LEN` (src/co/tpdo.c lines 710-715 and 773-776). A consumer's object dispatching
list (0x1FD0-0x1FFF, UNSIGNED64 entries) says where a SAM frame's value goes: bits 0-7 the
producer's node-ID, 8-15 its first sub-index, 16-31 its index, 32-39 the consumer's first
sub-index, 40-55 its index, 56-63 the block size (sub-indices in a row, 0 as 1): as Lely's
`co_dev_map_sam_mpdo` reads it (src/co/pdo.c lines 243-291; it takes the block size from
bit 54, CiA 301 from bit 56: here bit 56). The object scanner list (0x1FA0-0x1FCF) only
says what a producer may send and is not followed.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

SAM, DAM = 0xFE, 0xFF  # mapping sub 0
MODES = {SAM: "sam", DAM: "dam"}
FRAME_BYTES = 8
VALUE_BYTE = 4  # the value starts here
VALUE_BITS = 32
ADDRESS_DAM = 0x80  # byte 0, bit 7
SCANNER_FIRST, SCANNER_LAST = 0x1FA0, 0x1FCF  # object scanner lists (a SAM producer's)
DISPATCH_FIRST, DISPATCH_LAST = 0x1FD0, 0x1FFF  # object dispatching lists (a consumer's)


def object_name(index: int, subindex: int) -> tuple[str, int] | None:
    """(name, data type) of a scanner or dispatching list entry, else None."""
    for first, last, name in (
        (SCANNER_FIRST, SCANNER_LAST, "Object scanner list"),
        (DISPATCH_FIRST, DISPATCH_LAST, "Object dispatching list"),
    ):
        if first <= index <= last:
            if subindex == 0:
                return f"{name} {index - first + 1}: number of entries", 0x05
            return f"{name} {index - first + 1}: entry {subindex}", 0x1B  # UNSIGNED64
    return None


def dispatched(entry: int, producer: int, index: int, subindex: int) -> tuple[int, int] | None:
    """The consumer's (index, sub-index) a dispatching list entry gives a SAM frame's object
    of `producer`, else None."""
    if not entry or entry & 0xFF != producer or (entry >> 16) & 0xFFFF != index:
        return None
    first = (entry >> 8) & 0xFF
    block = max((entry >> 56) & 0xFF, 1)
    if not first <= subindex < first + block:
        return None
    return (entry >> 40) & 0xFFFF, ((entry >> 32) & 0xFF) + subindex - first


class MpdoColumns(NamedTuple):
    """Per frame: DAM (else SAM), the node-ID, the object's index and sub-index."""

    dam: np.ndarray
    node: np.ndarray
    index: np.ndarray
    subindex: np.ndarray


def split(data: np.ndarray) -> MpdoColumns:
    """The address and object of n MPDO frames, (n, 8) uint8 -> columns."""
    data = np.asarray(data, np.uint8)
    return MpdoColumns(
        (data[:, 0] & ADDRESS_DAM) != 0,
        (data[:, 0] & 0x7F).astype(np.int16),
        data[:, 1].astype(np.int64) | (data[:, 2].astype(np.int64) << 8),
        data[:, 3].astype(np.int64),
    )


def fields(dam: bool, node: int, index: int, subindex: int) -> dict:
    """The JSONL `mpdo` field of one frame: mode, the producer (SAM) or destination (DAM,
    0: every node) node-ID, the object."""
    who = "destination" if dam else "producer"
    return {"mode": "dam" if dam else "sam", who: node, "index": index, "subindex": subindex}


def text(fields: dict) -> str:
    """'MPDO to node 6 0x6200:01' / 'MPDO to all nodes ...' / 'MPDO from node 5 0x2000:01
    -> node 6 0x6200:01' (a SAM frame and the consumers' objects it is dispatched to)."""
    obj = f"0x{fields['index']:04X}:{fields['subindex']:02X}"
    if fields["mode"] == "dam":
        who = fields["destination"]
        return f"MPDO to {'all nodes' if who == 0 else f'node {who}'} {obj}"
    to = "".join(
        f" -> node {d['node']} 0x{d['index']:04X}:{d['subindex']:02X}"
        for d in fields.get("dispatched", ())
    )
    return f"MPDO from node {fields['producer']} {obj}{to}"
