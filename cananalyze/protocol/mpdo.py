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
bit 54, CiA 301 from bit 56: here bit 56). A SAM producer's object scanner list
(0x1FA0-0x1FCF, UNSIGNED32 entries; CiA 301 v4.2.0 7.5.2, objects 1FA0h-1FCFh) says which
of its objects it may send: bits 0-7 the first sub-index, 8-23 the index, 24-31 the block
size. Both layouts are the table LISTS.
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


class ListLayout(NamedTuple):
    """One kind of MPDO object list: its indices, entry type and entry fields."""

    name: str
    first: int
    last: int
    data_type: int  # of entries 1..
    fields: dict[str, tuple[int, int]]  # field -> (first bit, bits)


SCANNER, DISPATCHER = "scanner", "dispatcher"
LISTS = {
    SCANNER: ListLayout(
        "Object scanner list",
        0x1FA0,
        0x1FCF,
        0x07,  # UNSIGNED32
        {"subindex": (0, 8), "index": (8, 16), "block": (24, 8)},
    ),
    DISPATCHER: ListLayout(
        "Object dispatching list",
        0x1FD0,
        0x1FFF,
        0x1B,  # UNSIGNED64
        {
            "producer": (0, 8),
            "producer_subindex": (8, 8),
            "producer_index": (16, 16),
            "subindex": (32, 8),
            "index": (40, 16),
            "block": (56, 8),
        },
    ),
}
SCANNER_FIRST, SCANNER_LAST = LISTS[SCANNER].first, LISTS[SCANNER].last
DISPATCH_FIRST, DISPATCH_LAST = LISTS[DISPATCHER].first, LISTS[DISPATCHER].last


def object_name(index: int, subindex: int) -> tuple[str, int] | None:
    """(name, data type) of a scanner or dispatching list entry, else None."""
    for lst in LISTS.values():
        if lst.first <= index <= lst.last:
            if subindex == 0:
                return f"{lst.name} {index - lst.first + 1}: number of entries", 0x05
            return f"{lst.name} {index - lst.first + 1}: entry {subindex}", lst.data_type
    return None


def entry_fields(kind: str, entry: int) -> dict[str, int]:
    """The fields of one list entry (LISTS[kind]); a block size of 0 reads as 1."""
    out = {f: (entry >> at) & ((1 << bits) - 1) for f, (at, bits) in LISTS[kind].fields.items()}
    out["block"] = max(out["block"], 1)
    return out


def _within(first: int, block: int, subindex: int) -> bool:
    return first <= subindex < first + block


def scanned(entry: int, index: int, subindex: int) -> bool:
    """Whether an object scanner list entry lets its node send (index, sub-index)."""
    f = entry_fields(SCANNER, entry)
    return bool(entry) and f["index"] == index and _within(f["subindex"], f["block"], subindex)


def dispatched(entry: int, producer: int, index: int, subindex: int) -> tuple[int, int] | None:
    """The consumer's (index, sub-index) a dispatching list entry gives a SAM frame's object
    of `producer`, else None."""
    f = entry_fields(DISPATCHER, entry)
    if not entry or f["producer"] != producer or f["producer_index"] != index:
        return None
    if not _within(f["producer_subindex"], f["block"], subindex):
        return None
    return f["index"], f["subindex"] + subindex - f["producer_subindex"]


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
    -> node 6 0x6200:01' (a SAM frame and the consumers' objects it is dispatched to; marked
    when the producer's object scanner list is known and does not hold the object)."""
    obj = f"0x{fields['index']:04X}:{fields['subindex']:02X}"
    if fields["mode"] == "dam":
        who = fields["destination"]
        return f"MPDO to {'all nodes' if who == 0 else f'node {who}'} {obj}"
    to = "".join(
        f" -> node {d['node']} 0x{d['index']:04X}:{d['subindex']:02X}"
        for d in fields.get("dispatched", ())
    )
    text = f"MPDO from node {fields['producer']} {obj}{to}"
    if fields.get("scanned") is False:
        text += f"  [not in node {fields['producer']}'s object scanner list]"
    return text
