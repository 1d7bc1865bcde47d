"""SRDO (CiA 304 / EN 50325-5 safety-relevant data objects): the layouts, as data, and the text.

The reference is CANopenNode's implementation, `304/CO_SRDO.c` and `304/CO_SRDO.h`
(github.com/CANopenNode/CANopenNode, commit 9b8beed8):

- An SRDO is two frames: the normal one, then its bit inversion on the next COB-ID
  (`CO_SRDO_config`: `COB_ID1_normal + 1 == COB_ID2_inverted`, odd normal COB-ID from 0x101,
  inverted at most 0x180; CO_SRDO.c lines 498-501).
- Default COB-IDs are those of a node's first SRDO: 0x0FF + 2 * node-ID (normal) and
  0x100 + 2 * node-ID (inverted), node-IDs 1-64 (`CO_CAN_ID_SRDO_1 0x0FF` in
  301/CO_driver.h line 401, given to SRDO 1 only in CANopen.c line 1294; the node-ID
  added in CO_SRDO.c lines 467-473). Node 1's SRDO 1 is 0x101/0x102.
- Communication parameter 0x1301 + k (k = 0..63; CO_SRDO.c lines 442-455): sub 1
  information direction (u8: 0 not used, 1 produced, 2 consumed), sub 2 SCT, the refresh
  time (u16, ms), sub 3 SRVT, the validation time (u8, ms), sub 4 transmission type (u8,
  254), sub 5 COB-ID normal (u32), sub 6 COB-ID inverted (u32).
- Mapping parameter 0x1381 + k: sub 0 number of entries (even, at most 16), sub 1.. the
  entries, alternately the normal and the inverted object (`plain_inverted = i % 2`,
  CO_SRDO.c line 541): the normal frame carries the odd sub-indices' objects, the
  inverted frame the even ones'.
- 0x13FE configuration valid (u8, 0xA5 = valid: `CO_SRDO_VALID_MAGIC`, CO_SRDO.c line 42),
  0x13FF sub k+1 the CRC signature of SRDO k+1 (u16, CRC-16 CCITT; CO_SRDO.c lines 507-533).
- Timing as a consumer checks it (`CO_SRDO_process`, CO_SRDO.c lines 866-983): the
  inverted frame must arrive within SRVT of the normal one, and the next pair within SCT
  (the producer sends the normal frame every SCT, lines 836-842).
- 0x1300 the GFC parameter (u8): a producer sends GFC only when it is 1 (`CO_GFCsend`,
  304/CO_GFC.c: `if (*GFC->valid == 0x01)`).
- GFC, the global fail-safe command: COB-ID 0x001 (`CO_CAN_ID_GFC`, 301/CO_driver.h line
  397), no data (CiA 304).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cananalyze.protocol.crc import crc16
from cananalyze.protocol.pdo import signals_text
from cananalyze.protocol.pdo_map import MapEntry

U8, U16, U32 = 0x05, 0x06, 0x07

COUNT = 64  # SRDOs a device may have
COMM_BASE = 0x1301  # communication parameter of SRDO 1
MAP_BASE = 0x1381  # mapping parameter of SRDO 1
CONFIG_VALID = 0x13FE
VALID_MAGIC = 0xA5
CRC_INDEX = 0x13FF
GFC_COB_ID = 0x001
GFC_PARAMETER = 0x1300  # u8, 1: GFC valid (sent)
DEFAULT_NORMAL = 0x0FF  # + 2 * node-ID
DEFAULT_INVERTED = 0x100  # + 2 * node-ID
MAX_DEFAULT_NODE = 64
FIRST_COB, LAST_COB = 0x101, 0x180  # the range CO_SRDO_config accepts

# information direction (sub 1)
DIRECTIONS = {0: "not used", 1: "tx", 2: "rx"}

# communication parameter sub-index -> (name, data type)
COMM = {
    0: ("Highest sub-index supported", U8),
    1: ("Information direction", U8),
    2: ("Refresh time SCT (ms)", U16),
    3: ("Validation time SRVT (ms)", U8),
    4: ("Transmission type", U8),
    5: ("COB-ID normal", U32),
    6: ("COB-ID inverted", U32),
}
SUB_DIRECTION, SUB_SCT, SUB_SRVT, SUB_NORMAL, SUB_INVERTED = 1, 2, 3, 5, 6


def comm_number(index: int) -> int | None:
    """The SRDO number (1-64) of a communication parameter index, else None."""
    return index - COMM_BASE + 1 if COMM_BASE <= index < COMM_BASE + COUNT else None


def map_number(index: int) -> int | None:
    """The SRDO number (1-64) of a mapping parameter index, else None."""
    return index - MAP_BASE + 1 if MAP_BASE <= index < MAP_BASE + COUNT else None


def default_cob_ids(node: int) -> tuple[int, int] | None:
    """The default (normal, inverted) COB-IDs of a node's SRDO 1 (node-IDs 1-64), else None."""
    if 1 <= node <= MAX_DEFAULT_NODE:
        return DEFAULT_NORMAL + 2 * node, DEFAULT_INVERTED + 2 * node
    return None


def default_owner(normal: int) -> int | None:
    """The node whose SRDO 1 has this default normal COB-ID, else None."""
    node, odd = divmod(normal - DEFAULT_NORMAL, 2)
    return node if odd == 0 and 1 <= node <= MAX_DEFAULT_NODE else None


def object_name(index: int, subindex: int) -> tuple[str, int] | None:
    """(name, data type) of an SRDO object (0x1300-0x13FF), else None."""
    n = comm_number(index)
    if n is not None:
        if subindex in COMM:
            name, dtype = COMM[subindex]
            return f"SRDO{n} communication: {name}", dtype
        return None
    n = map_number(index)
    if n is not None:
        if subindex == 0:
            return f"SRDO{n} mapping: number of entries", U8
        kind = "normal" if subindex % 2 else "inverted"
        return f"SRDO{n} mapping: entry {subindex} ({kind})", U32
    if index == GFC_PARAMETER and subindex == 0:
        return "GFC parameter", U8
    if index == CONFIG_VALID and subindex == 0:
        return "SRDO configuration valid", U8
    if index == CRC_INDEX:
        if subindex == 0:
            return "Safety configuration checksum: highest sub-index supported", U8
        return f"Safety configuration checksum: SRDO{subindex}", U16
    return None


@dataclass(frozen=True)
class SrdoConfig:
    """One SRDO as configured: what the decoder and the `srdo` rule need."""

    node: int  # the node whose parameters these are
    number: int  # 1-64: 0x1301 + number - 1
    direction: int  # DIRECTIONS
    sct: int  # ms, 0: not known
    srvt: int  # ms, 0: not known
    cob_normal: int
    cob_inverted: int
    mapping: tuple[MapEntry, ...] = field(default_factory=tuple)  # the normal frame's objects
    data_length: int | None = None  # bytes of each frame by the mapping, None: not known

    @property
    def name(self) -> str:
        return f"srdo{self.number}"


def effective_cob_ids(node: int, number: int, normal: int, inverted: int) -> tuple[int, int]:
    """The COB-IDs in use: CANopenNode stores SRDO 1's default ones without the node-ID and
    adds 2 * node-ID (CO_SRDO.c lines 467-473), so 0x0FF/0x100 mean the node's default."""
    normal &= 0x7FF
    inverted &= 0x7FF
    default = (DEFAULT_NORMAL, DEFAULT_INVERTED)
    if number == 1 and (normal, inverted) == default and node <= MAX_DEFAULT_NODE:
        return normal + 2 * node, inverted + 2 * node
    return normal, inverted


def signature(
    node: int,
    number: int,
    direction: int,
    sct: int,
    srvt: int,
    cob_normal: int,
    cob_inverted: int,
    words: list[int],
) -> int:
    """The CRC signature (0x13FF:number) of an SRDO's parameters, as CO_SRDO_config computes
    it (CO_SRDO.c lines 507-533): CRC-16 CCITT from 0 over the direction (1 byte), SCT (2),
    SRVT (1), the COB-IDs in use (4 each), the number of entries (1), then each entry's
    sub-index (1) and value (4), every value little-endian."""
    normal, inverted = effective_cob_ids(node, number, cob_normal, cob_inverted)
    data = bytearray([direction & 0xFF])
    data += (sct & 0xFFFF).to_bytes(2, "little") + bytes([srvt & 0xFF])
    data += normal.to_bytes(4, "little") + inverted.to_bytes(4, "little")
    data.append(len(words) & 0xFF)
    for sub, word in enumerate(words, 1):
        data.append(sub)
        data += (word & 0xFFFFFFFF).to_bytes(4, "little")
    return crc16(bytes(data))


def not_inverted(normal: np.ndarray, inverted: np.ndarray, length: np.ndarray) -> np.ndarray:
    """Per pair: whether any of the first `length` bytes of the inverted frame is not the
    bit inversion of the normal frame's (CO_SRDO.c lines 887-894). (n, 8) uint8 each."""
    differ = (normal ^ inverted) != 0xFF
    within = np.arange(normal.shape[1])[None, :] < np.asarray(length)[:, None]
    return (differ & within).any(axis=1)


def annotation(number: int, inverted: bool, fields: dict) -> str:
    """'SRDO1 normal  speed=3' (its signals: the pair is decoded once, from the normal
    frame) or 'SRDO1 inverted'."""
    text = f"SRDO{number} {'inverted' if inverted else 'normal'}"
    if fields.get("signals"):
        text += "  " + signals_text(fields)
    if fields.get("pdo_problem"):
        text += f"  [{fields['pdo_problem']}]"
    return text


GFC_TEXT = "GFC global fail-safe command"
