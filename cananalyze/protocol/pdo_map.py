"""PDO mapping and communication parameters as plain values.

These are what the PDO decoder needs and what the network model changes when it
sees SDO writes to 0x1400-/0x1600-/0x1800-/0x1A00- objects, so they carry no
reference to an object dictionary.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

COB_ID_INVALID = 0x80000000  # CiA 301: bit 31 set = PDO does not exist / not valid
COB_ID_29BIT = 0x20000000  # bit 29: 29-bit identifier


@dataclass(frozen=True)
class MapEntry:
    """One mapped object in a PDO: where it comes from, its width and how to show it."""

    index: int
    subindex: int
    bits: int
    name: str
    datatype: int
    unit: str | None = None
    scale: float | None = None
    offset: float = 0.0


@dataclass
class PdoConfig:
    """Communication and mapping parameters of one RPDO or TPDO (CiA 301 units)."""

    direction: Literal["tx", "rx"]
    number: int  # 1-based: TPDO1 is 0x1800/0x1A00
    cob_id: int  # identifier only, flag bits removed
    valid: bool
    transmission_type: int
    inhibit_time: int  # multiples of 100 us
    event_timer: int  # ms
    mapping: list[MapEntry] = field(default_factory=list)
    length: int | None = None  # expected bytes when the mapping is unknown (network file)
    # the mapping is a CiA 4xx profile's default, not the device's (devices/generic.py):
    # decoded as far as a frame reaches, its length not judged
    assumed: bool = False
    # an MPDO (protocol/mpdo.py): "sam" or "dam" when the mapping's count is 0xFE / 0xFF
    mpdo: str | None = None

    @property
    def bits(self) -> int:
        return sum(e.bits for e in self.mapping)

    @property
    def expected_bytes(self) -> int | None:
        """The frame length this PDO should have: its mapping's, else the declared length,
        else None (not known: nothing to check)."""
        if self.assumed:
            return None
        if self.mpdo:
            return 8  # CiA 301: every MPDO frame has 8 bytes (protocol/mpdo.py)
        if self.mapping:
            return (self.bits + 7) // 8
        return self.length


def split_mapping_word(word: int) -> tuple[int, int, int]:
    """(index, subindex, bits) of a CiA 301 mapping entry 0xIIIISSLL."""
    return (word >> 16) & 0xFFFF, (word >> 8) & 0xFF, word & 0xFF


def split_cob_id(value: int) -> tuple[int, bool]:
    """(identifier, valid) of a PDO COB-ID parameter value."""
    mask = 0x1FFFFFFF if value & COB_ID_29BIT else 0x7FF
    return value & mask, not value & COB_ID_INVALID
