"""What the analyser believes one node's communication configuration is, right now.

Kept as the raw CiA 301 object values (COB-ID words with their flag bits, mapping
words), because that is what SDO writes change one sub-index at a time: a mapping
is rebuilt from its words whenever a word, the count in sub-index 0, or an object
that changes signal units (the profile's context objects) is written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from ..protocol.datatypes import DUMMY_INDICES
from .pdo_map import COB_ID_INVALID, MapEntry, PdoConfig, split_cob_id, split_mapping_word
from .profile import DeviceProfile

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

# Which part of the model a write touched: the model re-binds COB-IDs for these.
TOUCHES_COB_IDS = {"pdo", "emcy", "sync", "context"}


@dataclass
class PdoState:
    """Raw communication and mapping parameters of one PDO."""

    direction: Direction
    number: int
    cob_raw: int = COB_ID_INVALID
    transmission_type: int = 0
    inhibit_time: int = 0
    event_timer: int = 0
    count: int = 0
    words: dict[int, int] = field(default_factory=dict)  # mapping sub-index -> 0xIIIISSLL

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


@dataclass
class NodeConfig:
    """One node: its profile, how we know it, and its current communication parameters."""

    node: int
    profile: DeviceProfile | None = None
    identified_by: str = "unknown"
    identity: dict[str, int | str] = field(default_factory=dict)
    pdos: dict[tuple[Direction, int], PdoState] = field(default_factory=dict)
    heartbeat_ms: int | None = None  # 0x1017
    consumer_heartbeat: dict[int, int] = field(
        default_factory=dict
    )  # 0x1016 sub -> raw (node<<16 | ms)
    guard_time_ms: int | None = None  # 0x100C
    life_time_factor: int | None = None  # 0x100D
    sync_cob_raw: int | None = None  # 0x1005
    sync_period_us: int | None = None  # 0x1006
    sync_window_us: int | None = None  # 0x1007
    emcy_cob_raw: int | None = None  # 0x1014
    emcy_inhibit: int | None = None  # 0x1015, multiples of 100 us
    context: dict[tuple[int, int], int] = field(default_factory=dict)  # unit-changing objects
    sdo_channels: list[tuple[int, int]] = field(default_factory=list)  # (request, response) COB-IDs

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
                state.transmission_type = int(profile.value(comm + n, 2, node) or 0)
                state.inhibit_time = int(profile.value(comm + n, 3, node) or 0)
                state.event_timer = int(profile.value(comm + n, 5, node) or 0)
                state.count = int(profile.value(mapping + n, 0, node) or 0)
                for sub in range(1, 65):
                    word = profile.value(mapping + n, sub, node)
                    if isinstance(word, int):
                        state.words[sub] = word
                cfg.pdos[(direction, n + 1)] = state
        for attr, index in (
            ("heartbeat_ms", 0x1017),
            ("guard_time_ms", 0x100C),
            ("life_time_factor", 0x100D),
            ("sync_cob_raw", 0x1005),
            ("sync_period_us", 0x1006),
            ("sync_window_us", 0x1007),
            ("emcy_cob_raw", 0x1014),
            ("emcy_inhibit", 0x1015),
        ):
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

    def pdo_config(self, state: PdoState) -> PdoConfig:
        """The decoder's view of one PDO: mapping entries with names and units in force."""
        mapping: list[MapEntry] = []
        for sub in range(1, state.count + 1):
            word = state.words.get(sub)
            if word:
                mapping.extend(entries_for(self.profile, word, self.context))
        return PdoConfig(
            state.direction,
            state.number,
            state.cob_id,
            state.valid,
            state.transmission_type,
            state.inhibit_time,
            state.event_timer,
            mapping,
        )

    def apply(self, index: int, sub: int, value: int) -> str | None:
        """Follow one written (or read back) object value; say which part changed, if any."""
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
            else:
                state.words[sub] = value
            return "pdo"
        if (index, sub) in self.context_objects():
            self.context[(index, sub)] = value
            return "context"
        simple = {
            0x1017: "heartbeat_ms",
            0x100C: "guard_time_ms",
            0x100D: "life_time_factor",
            0x1006: "sync_period_us",
            0x1007: "sync_window_us",
            0x1015: "emcy_inhibit",
        }
        if index in simple and sub == 0:
            setattr(self, simple[index], value)
            return "timing"
        if index == 0x1016 and sub >= 1:
            self.consumer_heartbeat[sub] = value
            return "timing"
        if index == 0x1005 and sub == 0:
            self.sync_cob_raw = value
            return "sync"
        if index == 0x1014 and sub == 0:
            self.emcy_cob_raw = value
            return "emcy"
        if 0x1200 <= index <= 0x12FF:
            return "sdo"
        return None
