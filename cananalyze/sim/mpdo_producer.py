"""A simulated node's MPDOs (CiA 301 multiplexed PDOs): which object each frame carries.

A TPDO whose mapping count (0x1A00+n:0) is 0xFE sends SAM-MPDOs: the objects of the node's
object scanner lists (0x1FA0-0x1FCF), one per frame in turn; 0xFF sends DAM-MPDOs of the
object its mapping entry 1 names, to every node (destination 0). The layout is
protocol/mpdo.py's (the frame as lely-core builds it); a network file's `mpdo = "sam"`
and `object_scanner_list` set these objects as stored parameters, the keys the decoder
reads. An object the node's dictionary lacks carries the frame counter.
"""

from __future__ import annotations

import struct

from cananalyze.protocol import mpdo
from cananalyze.sim.dictionary import Dictionary


def mode(od: Dictionary, n: int) -> int | None:
    """mpdo.SAM or mpdo.DAM when TPDO n is an MPDO, else None."""
    count = od.get(0x1A00 + n - 1, 0)
    return count if count in mpdo.MODES else None


def objects(od: Dictionary, n: int) -> list[tuple[int, int]]:
    """The (index, sub-index) TPDO n's MPDO frames carry, in turn."""
    if mode(od, n) == mpdo.DAM:
        word = od.get(0x1A00 + n - 1, 1)
        return [(word >> 16, (word >> 8) & 0xFF)] if word else []
    lst = mpdo.LISTS[mpdo.SCANNER]
    out = []
    for index in range(lst.first, lst.last + 1):
        for s in range(1, od.get(index, 0) + 1):
            entry = od.get(index, s)
            if entry:
                f = mpdo.entry_fields(mpdo.SCANNER, entry)
                out += [(f["index"], f["subindex"] + b) for b in range(f["block"])]
    return out


def frame(od: Dictionary, node_id: int, n: int, k: int) -> bytes:
    """The k-th MPDO frame of TPDO n (b"" when it has no object to send)."""
    objs = objects(od, n)
    if not objs:
        return b""
    index, sub = objs[k % len(objs)]
    raw = od.values.get((index, sub)) or (k // len(objs)).to_bytes(4, "little")
    dam = mode(od, n) == mpdo.DAM
    head = bytes([mpdo.ADDRESS_DAM if dam else node_id]) + struct.pack("<HB", index, sub)
    return head + raw[:4].ljust(4, b"\0")
