"""A simulated node's produced SRDOs (CiA 304): pairs of frames as CANopenNode sends them.

Configured by the node's own objects (protocol/srdo.py's layout), which a network file's
`[nodes.N.srdo.K]` fills as stored parameters, the same keys the decoder reads: every SRDO
whose information direction (0x1301+k:1) is 1 (produced) sends, while the node is
operational, its normal frame (the odd mapping entries' objects) and, within SRVT, the
bit-inverted copy on the next COB-ID (CO_SRDO.c line 541 and lines 887-894), every
`REFRESH` of its SCT. A mapped object the node's dictionary lacks carries the pair counter.
Scenarios switch on faults by windows (Faults.srdo_not_inverted, Faults.srdo_late): the
first pair in each window has the fault; after a pair not inverted, a node whose GFC
parameter (0x1300) is 1 sends GFC, as CANopenNode's `CO_GFCsend` does when valid.
"""

from __future__ import annotations

import random
from typing import NamedTuple, Protocol

from cananalyze.protocol import srdo as layout
from cananalyze.protocol.nmt import OPERATIONAL
from cananalyze.sim.dictionary import Dictionary
from cananalyze.sim.engine import Simulation


class SimNode(Protocol):
    """What of sim/node.py's SimNode the producer uses (node.py imports this module)."""

    node_id: int
    od: Dictionary
    sim: Simulation
    state: int
    rng: random.Random
    faults: object  # node.Faults: srdo_not_inverted, srdo_late

    @property
    def generation(self) -> int: ...


REFRESH = 0.8  # of SCT: the producer's cycle, so the next pair is inside SCT on a busy bus
INVERTED_DELAY = 0.0003  # s after the normal frame, plus up to as much again (seeded)
LATE_BY = 0.005  # s past SRVT: the fault `srdo_late`


class Produced(NamedTuple):
    number: int
    sct: float  # s
    srvt: float  # s
    normal: int
    inverted: int
    entries: tuple[int, ...]  # the normal frame's mapping words (odd sub-indices)


def produced(node: SimNode) -> list[Produced]:
    """The SRDOs the node's dictionary says it produces (direction 1, SCT and a mapping)."""
    od, out = node.od, []
    for k in range(layout.COUNT):
        comm, mapping = layout.COMM_BASE + k, layout.MAP_BASE + k
        if od.get(comm, layout.SUB_DIRECTION) != 1 or not od.get(comm, layout.SUB_SCT):
            continue
        count = od.get(mapping, 0)
        words = tuple(od.get(mapping, s) for s in range(1, count + 1, 2))
        if not words:
            continue
        normal, inverted = layout.effective_cob_ids(
            node.node_id,
            k + 1,
            od.get(comm, layout.SUB_NORMAL),
            od.get(comm, layout.SUB_INVERTED),
        )
        sct = od.get(comm, layout.SUB_SCT) / 1000.0
        srvt = od.get(comm, layout.SUB_SRVT) / 1000.0
        out.append(Produced(k + 1, sct, srvt, normal, inverted, words))
    return out


def start(node: SimNode) -> None:
    """Start every produced SRDO's cycle (the node has just become operational)."""
    gen = node.generation
    for srdo in produced(node):
        node.sim.after(0.0, lambda s=srdo: _pair(node, gen, s, 0))


def _payload(node: SimNode, srdo: Produced, k: int) -> bytes:
    acc = bits = 0
    for word in srdo.entries:
        index, sub, length = word >> 16, (word >> 8) & 0xFF, word & 0xFF
        raw = node.od.values.get((index, sub))
        value = int.from_bytes(raw, "little") if raw else k
        acc |= (value & ((1 << length) - 1)) << bits
        bits += length
    return acc.to_bytes((bits + 7) // 8, "little")[:8]


def _fault(windows: list[tuple[float, float]], now: float) -> bool:
    """Whether a fault window holds `now`: it applies to the node's first pair in it, once
    (the window is used up), so one pair is faulty whatever the SCT."""
    for w in windows:
        if w[0] <= now < w[1]:
            windows.remove(w)
            return True
    return False


def _pair(node: SimNode, gen: int, srdo: Produced, k: int) -> None:
    if gen != node.generation or node.state != OPERATIONAL:
        return
    normal = _payload(node, srdo, k)
    inverted = bytes(b ^ 0xFF for b in normal)
    gfc = False
    if normal and _fault(node.faults.srdo_not_inverted, node.sim.now):
        inverted = bytes([inverted[0] ^ 0x01]) + inverted[1:]  # one bit not inverted
        gfc = node.od.get(layout.GFC_PARAMETER, 0) == 1  # the application's GFC, if valid
    delay = INVERTED_DELAY + node.rng.uniform(0, INVERTED_DELAY)
    if _fault(node.faults.srdo_late, node.sim.now):
        delay = srdo.srvt + LATE_BY
    node.sim.send(node, srdo.normal, normal)

    def second() -> None:
        if gen == node.generation and node.state == OPERATIONAL:
            node.sim.send(node, srdo.inverted, inverted)
            if gfc:
                node.sim.send(node, layout.GFC_COB_ID, b"")

    node.sim.after(delay, second)
    node.sim.after(REFRESH * srdo.sct, lambda: _pair(node, gen, srdo, k + 1))
