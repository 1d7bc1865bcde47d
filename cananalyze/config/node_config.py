"""What the analyser believes one node's communication configuration is, right now.

Kept as the raw CiA 301 object values (COB-ID words with their flag bits, mapping
words), because that is what SDO writes change one sub-index at a time: a mapping
is rebuilt from its words whenever a word, the count in sub-index 0, or an object
that changes signal units (the profile's context objects) is written.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

from cananalyze.devices.profile import DeviceProfile
from cananalyze.protocol import srdo as srdo_layout
from cananalyze.protocol.datatypes import DUMMY_INDICES
from cananalyze.protocol.mpdo import MODES as MPDO_MODES
from cananalyze.protocol.pdo_map import (
    COB_ID_INVALID,
    MapEntry,
    PdoConfig,
    split_cob_id,
    split_mapping_word,
)

Direction = Literal["tx", "rx"]
_UINT_BY_BITS = {
    1: 0x01,
    8: 0x05,
    16: 0x06,
    24: 0x16,
    32: 0x07,
    40: 0x18,
    48: 0x19,
    56: 0x1A,
    64: 0x1B,
}

# Transmission type of a PDO nobody described: 255 (event-driven, manufacturer-specific)
# asks nothing of the SYNC rules, and with no inhibit time or event timer nothing of the
# asynchronous ones, so an unknown PDO is never judged against a guess.
UNKNOWN_TYPE = 255

# Which part of the model a write touched: the model re-binds COB-IDs for these.
TOUCHES_COB_IDS = {"pdo", "emcy", "sync", "context", "srdo"}


@dataclass
class SrdoState:
    """Raw communication and mapping parameters of one SRDO (protocol/srdo.py's layout)."""

    number: int
    direction: int = 0  # sub 1: 0 not used (until a write or the profile says)
    sct: int = 0  # sub 2, ms
    srvt: int = 0  # sub 3, ms
    cob_normal: int | None = None  # sub 5
    cob_inverted: int | None = None  # sub 6
    count: int = 0
    words: dict[int, int] = field(default_factory=dict)  # mapping sub-index -> 0xIIIISSLL

    def set(self, sub: int, value: int) -> bool:
        """Follow one communication parameter value; False for a sub-index not followed."""
        if sub == srdo_layout.SUB_DIRECTION:
            self.direction = value
        elif sub == srdo_layout.SUB_SCT:
            self.sct = value
        elif sub == srdo_layout.SUB_SRVT:
            self.srvt = value
        elif sub == srdo_layout.SUB_NORMAL:
            self.cob_normal = value
        elif sub == srdo_layout.SUB_INVERTED:
            self.cob_inverted = value
        else:
            return False
        return True


@dataclass
class PdoState:
    """Raw communication and mapping parameters of one PDO."""

    direction: Direction
    number: int
    cob_raw: int = COB_ID_INVALID
    transmission_type: int = 255  # UNKNOWN_TYPE until a profile, the file or the log says
    inhibit_time: int = 0
    event_timer: int = 0
    count: int = 0
    words: dict[int, int] = field(default_factory=dict)  # mapping sub-index -> 0xIIIISSLL
    length: int | None = None  # expected bytes while the mapping is unknown (network file)
    assumed: bool = False  # mapping from a CiA 4xx profile's defaults, until the log maps it

    @property
    def cob_id(self) -> int:
        return split_cob_id(self.cob_raw)[0]

    @property
    def valid(self) -> bool:
        return split_cob_id(self.cob_raw)[1]


def predefined_cob(direction: Direction, number: int, node: int) -> int:
    """CiA 301 predefined connection set COB-ID word of PDO 1-4; others start not valid."""
    if 1 <= number <= 4 and 1 <= node <= 127:
        return (0x180 if direction == "tx" else 0x200) + 0x100 * (number - 1) + node
    return COB_ID_INVALID


def entries_for(
    profile: DeviceProfile | None, word: int, context: dict[tuple[int, int], int]
) -> list[MapEntry]:
    """MapEntries of one mapping word: the profile's names and units, else a generic name."""
    index, sub, bits = split_mapping_word(word)
    if profile is not None:
        return profile.map_entries(index, sub, bits, context)
    if index in DUMMY_INDICES:
        return [MapEntry(index, sub, bits, f"dummy_{index:04x}", index)]
    return [MapEntry(index, sub, bits, f"obj_{index:04x}_{sub:02x}", _UINT_BY_BITS.get(bits, 0x1B))]


def _shown_as(entry: MapEntry, spec: dict | None) -> MapEntry:
    """A mapped object with the network file's name, unit and scaling over the profile's."""
    if not spec:
        return entry
    return replace(
        entry,
        name=spec.get("name", entry.name),
        unit=spec.get("unit", entry.unit),
        scale=spec.get("scale", entry.scale),
        offset=spec.get("offset", entry.offset),
    )


@dataclass
class NodeConfig:
    """One node: its profile, how we know it, and its current communication parameters."""

    node: int
    profile: DeviceProfile | None = None
    identified_by: str = "unknown"
    identity: dict[str, int | str] = field(default_factory=dict)
    pdos: dict[tuple[Direction, int], PdoState] = field(default_factory=dict)
    # what decoding needs of the rest (timing values live in NetworkModel.known)
    sync_cob_raw: int | None = None  # 0x1005
    emcy_cob_raw: int | None = None  # 0x1014
    context: dict[tuple[int, int], int] = field(default_factory=dict)  # unit-changing objects
    sdo_channels: list[tuple[int, int]] = field(default_factory=list)  # (request, response) COB-IDs
    srdos: dict[int, SrdoState] = field(default_factory=dict)  # SRDO number -> parameters
    # the network file's `signals`: (index, subindex) -> name, unit, scale, offset
    signals: dict[tuple[int, int], dict] = field(default_factory=dict)

    @classmethod
    def from_profile(cls, node: int, profile: DeviceProfile | None, how: str) -> NodeConfig:
        """Defaults of the profile's object dictionary, $NODEID resolved for `node`."""
        cfg = cls(node, profile, how if profile is not None or how != "unknown" else "unknown")
        if profile is None:
            return cfg
        for ctx in cfg.context_objects():
            value = profile.value(*ctx, node)
            if isinstance(value, int):
                cfg.context[ctx] = value
        for direction, comm, mapping in (("rx", 0x1400, 0x1600), ("tx", 0x1800, 0x1A00)):
            for n in range(512):
                cob = profile.value(comm + n, 1, node)
                if cob is None:
                    continue
                state = PdoState(
                    direction, n + 1, int(cob) if isinstance(cob, int) else COB_ID_INVALID
                )
                ttype = profile.value(comm + n, 2, node)
                state.transmission_type = ttype if isinstance(ttype, int) else UNKNOWN_TYPE
                state.inhibit_time = int(profile.value(comm + n, 3, node) or 0)
                state.event_timer = int(profile.value(comm + n, 5, node) or 0)
                state.count = int(profile.value(mapping + n, 0, node) or 0)
                state.assumed = profile.generic
                for sub in range(1, 65):
                    word = profile.value(mapping + n, sub, node)
                    if isinstance(word, int):
                        state.words[sub] = word
                cfg.pdos[(direction, n + 1)] = state
        for k in range(srdo_layout.COUNT):
            comm = srdo_layout.COMM_BASE + k
            if profile.value(comm, srdo_layout.SUB_DIRECTION, node) is None:
                continue
            state = cfg.srdo(k + 1)
            for sub in srdo_layout.COMM:
                value = profile.value(comm, sub, node)
                if isinstance(value, int):
                    state.set(sub, value)
            state.count = int(profile.value(srdo_layout.MAP_BASE + k, 0, node) or 0)
            for sub in range(1, 17):
                word = profile.value(srdo_layout.MAP_BASE + k, sub, node)
                if isinstance(word, int):
                    state.words[sub] = word
        for attr, index in (("sync_cob_raw", 0x1005), ("emcy_cob_raw", 0x1014)):
            value = profile.value(index, 0, node)
            if isinstance(value, int):
                setattr(cfg, attr, value)
        return cfg

    def context_objects(self) -> set[tuple[int, int]]:
        """Objects whose value changes how the profile decodes signals (e.g. DAT 7014 0x2107)."""
        side = self.profile.sidecar if self.profile is not None else None
        if side is None:
            return set()
        return {spec.context for spec in side.signals.values() if spec.context}

    def pdo(self, direction: Direction, number: int) -> PdoState:
        """A PDO's state; one first seen by a write starts at its predefined COB-ID (PDO 1-4)."""
        state = self.pdos.get((direction, number))
        if state is None:
            state = PdoState(direction, number, predefined_cob(direction, number, self.node))
            self.pdos[(direction, number)] = state
        return state

    def srdo(self, number: int) -> SrdoState:
        state = self.srdos.get(number)
        if state is None:
            state = self.srdos[number] = SrdoState(number)
        return state

    def srdo_config(self, state: SrdoState) -> srdo_layout.SrdoConfig | None:
        """The decoder's view of one SRDO, None while it is not in use or its COB-IDs are not
        known. The mapping: the normal frame's objects (odd sub-indices), none while an
        entry is not known; the data length of each frame from it."""
        if state.direction not in (1, 2):
            return None
        if state.cob_normal is None or state.cob_inverted is None:
            return None
        normal, inverted = srdo_layout.effective_cob_ids(
            self.node, state.number, state.cob_normal, state.cob_inverted
        )
        mapping: list[MapEntry] = []
        length: int | None = None
        words = [state.words.get(sub) for sub in range(1, state.count + 1)]
        if state.count and None not in words:
            for word in words[0::2]:
                mapping.extend(entries_for(self.profile, word, self.context))  # type: ignore[arg-type]
            length = (sum(e.bits for e in mapping) + 7) // 8
            if self.signals:
                mapping = [_shown_as(e, self.signals.get((e.index, e.subindex))) for e in mapping]
        return srdo_layout.SrdoConfig(
            self.node,
            state.number,
            state.direction,
            state.sct,
            state.srvt,
            normal,
            inverted,
            tuple(mapping),
            length,
        )

    def pdo_config(self, state: PdoState) -> PdoConfig:
        """The decoder's view of one PDO: mapping entries with names and units in force.

        A mapping with an entry not known yet (a master reads 0x1A0x:0, then each entry,
        while the PDO runs) is not known at all: a part of it would be a wrong length."""
        mapping: list[MapEntry] = []
        mpdo = MPDO_MODES.get(state.count)
        for sub in range(1, 0 if mpdo else state.count + 1):
            word = state.words.get(sub)
            if word is None:
                mapping = []
                break
            if word:
                mapping.extend(entries_for(self.profile, word, self.context))
        if self.signals:
            mapping = [_shown_as(e, self.signals.get((e.index, e.subindex))) for e in mapping]
        return PdoConfig(
            state.direction,
            state.number,
            state.cob_id,
            state.valid,
            state.transmission_type,
            state.inhibit_time,
            state.event_timer,
            mapping,
            state.length,
            assumed=state.assumed,
            mpdo=mpdo,
        )

    def apply(self, index: int, sub: int, value: int) -> str | None:
        """Follow one written (or read back) object value; say which part of what decoding
        needs changed, if any (timing values are kept by the model, not here)."""
        if 0x1400 <= index <= 0x1BFF and (index & 0x1FF) < 0x200:
            direction: Direction = "rx" if index < 0x1800 else "tx"
            base = index & ~0x1FF
            n = index - base + 1
            state = self.pdo(direction, n)
            if base in (0x1400, 0x1800):
                if sub == 1:
                    state.cob_raw = value
                elif sub == 2:
                    state.transmission_type = value
                elif sub == 3:
                    state.inhibit_time = value
                elif sub == 5:
                    state.event_timer = value
                else:
                    return None
            elif sub == 0:
                state.count = value
                state.assumed = False
            else:
                state.words[sub] = value
                state.assumed = False
            return "pdo"
        number = srdo_layout.comm_number(index)
        if number is not None:
            return "srdo" if self.srdo(number).set(sub, value) else None
        number = srdo_layout.map_number(index)
        if number is not None:
            state = self.srdo(number)
            if sub == 0:
                state.count = value
            else:
                state.words[sub] = value
            return "srdo"
        if (index, sub) in self.context_objects():
            self.context[(index, sub)] = value
            return "context"
        if index == 0x1005 and sub == 0:
            self.sync_cob_raw = value
            return "sync"
        if index == 0x1014 and sub == 0:
            self.emcy_cob_raw = value
            return "emcy"
        if 0x1200 <= index <= 0x12FF:
            return "sdo"
        return None
