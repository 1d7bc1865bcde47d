"""Device profiles: an object dictionary (EDS/DCF) plus the sidecar's display knowledge.

Built-in profiles (`builtin.py`) live in `decoders/`; a user's own EDS/DCF loads the same
way, with the sidecar beside it if there is one. The network model asks a
profile for a node's default PDOs, the decoder asks it for signal names and units and
for the meaning of vendor EMCY bytes, and identification matches SDO-read identity
objects against the built-ins.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from cananalyze.core.text import printable, printable_or_none
from cananalyze.devices.eds import ObjectInfo, effective_value, info_of, read_od, variable
from cananalyze.devices.od_facts import UNSURE, OdFacts, load_facts
from cananalyze.devices.sidecar import Sidecar, load_sidecar
from cananalyze.protocol.datatypes import DATA_TYPES, DUMMY_INDICES
from cananalyze.protocol.pdo_map import MapEntry, PdoConfig, split_cob_id, split_mapping_word

BOOLEAN = 0x01
_UINT_BY_BITS = {8: 0x05, 16: 0x06, 24: 0x16, 32: 0x07, 40: 0x18, 48: 0x19, 56: 0x1A, 64: 0x1B}


def signal_name(name: str) -> str:
    """Object name as a column-friendly signal name ("Read Input 8 bit" -> "read_input_8_bit")."""
    return re.sub(r"[^0-9a-zA-Z]+", "_", name).strip("_").lower() or "value"


@dataclass
class DeviceProfile:
    key: str
    name: str
    vendor_id: int | None
    product_code: int | None
    device_type: int | None
    device_name: str | None
    notes: list[str]
    source: str
    # what decoding asks of the dictionary, without canopen (`od_facts`)
    facts: OdFacts = field(repr=False)
    sidecar: Sidecar | None = field(default=None, repr=False)
    node_id: int | None = None  # from a DCF's [DeviceComissioning], if any
    generic: bool = False  # a CiA 4xx profile's defaults, not a device's own dictionary
    # canopen's ObjectDictionary of the file: parsed already, or when first asked (`od`)
    parsed: object = field(default=None, repr=False, compare=False)
    load_od: Callable[[], object] | None = field(default=None, repr=False, compare=False)

    @property
    def od(self):
        """canopen's ObjectDictionary (the simulator, DCF output and `diff` read it whole)."""
        if self.parsed is None:
            self.parsed = self.load_od()
        return self.parsed

    @property
    def family(self) -> int | None:
        """402 or 401 when the device type names CiA 402 (drives) or CiA 401 (I/O)."""
        from cananalyze.devices.family import family

        return family(self.device_type)

    # --- object dictionary -------------------------------------------------
    def _variable(self, index: int, subindex: int):
        """The facts' variable, or canopen's where the facts are not sure."""
        var = self.facts.variable(index, subindex)
        return variable(self.od, index, subindex) if var is UNSURE else var

    def object(self, index: int, subindex: int = 0) -> ObjectInfo | None:
        return info_of(self._variable(index, subindex), index, subindex, self.node_id)

    def value(self, index: int, subindex: int, node_id: int | None = None):
        """Effective value (DCF value, else default) with $NODEID resolved for node_id."""
        var = self._variable(index, subindex)
        if var is None:
            return None
        return effective_value(var, node_id if node_id is not None else self.node_id)

    # --- signals -------------------------------------------------------------
    def signal_meta(
        self, index: int, subindex: int, context: dict[tuple[int, int], int] | None = None
    ) -> tuple[str, str | None, float | None, float]:
        """(name, unit, scale, offset) of a mapped object.

        context holds current values of objects that change units (e.g. DAT 7014
        sensor type 0x2107); when absent, the profile's default value is used.
        """
        spec = self.sidecar.signals.get((index, subindex)) if self.sidecar else None
        if spec is None:
            info = self.object(index, subindex)
            name = signal_name(info.name) if info else f"obj_{index:04x}_{subindex:02x}"
            return name, self._profile_unit(index, subindex), None, 0.0
        if spec.unit_table and spec.context and self.sidecar:
            ctx = (context or {}).get(spec.context)
            if ctx is None:
                ctx = self.value(*spec.context)
            choice = self.sidecar.unit_tables.get(spec.unit_table, {}).get(ctx)
            if choice is not None:
                return spec.name, choice.unit, choice.scale, choice.offset
            return spec.name, None, None, 0.0
        return spec.name, spec.unit, spec.scale, spec.offset

    def _profile_unit(self, index: int, subindex: int) -> str | None:
        """A CiA 402 object's unit when the EDS names the profile but says no unit."""
        if self.family != 402:
            return None
        from cananalyze.devices.family import object_unit

        return object_unit(402, index, subindex)

    def map_entries(
        self,
        index: int,
        subindex: int,
        bits: int,
        context: dict[tuple[int, int], int] | None = None,
    ) -> list[MapEntry]:
        """MapEntries for one mapping word; a byte the sidecar splits becomes booleans.

        The network model calls this for every mapping it sees written by SDO.
        """
        if index in DUMMY_INDICES:
            return [MapEntry(index, subindex, bits, f"dummy_{index:04x}", index)]
        info = self.object(index, subindex)
        datatype = info.datatype if info and info.datatype in DATA_TYPES else 0
        if not datatype:
            datatype = BOOLEAN if bits == 1 else _UINT_BY_BITS.get(bits, 0x1B)
        name, unit, scale, offset = self.signal_meta(index, subindex, context)
        spec = self.sidecar.signals.get((index, subindex)) if self.sidecar else None
        if spec is not None and spec.split and bits >= len(spec.split):
            out = [MapEntry(index, subindex, 1, n, BOOLEAN) for n in spec.split]
            if bits > len(spec.split):  # unused high bits: padding, like a dummy entry
                out.append(MapEntry(0x0001, 0, bits - len(spec.split), "unused", BOOLEAN))
            return out
        return [MapEntry(index, subindex, bits, name, datatype, unit, scale, offset)]

    def pdos(
        self, node_id: int | None = None, context: dict[tuple[int, int], int] | None = None
    ) -> list[PdoConfig]:
        """Every PDO the dictionary defines, with defaults resolved for node_id."""
        node = node_id if node_id is not None else self.node_id
        out: list[PdoConfig] = []
        for direction, comm_base, map_base in (("rx", 0x1400, 0x1600), ("tx", 0x1800, 0x1A00)):
            for n in range(512):
                if self._variable(comm_base + n, 1) is None:
                    continue
                cob_raw = self.value(comm_base + n, 1, node)
                if cob_raw is None:
                    cob_raw = 0x80000000  # unresolvable ($NODEID without a node id): not valid
                cob_id, valid = split_cob_id(int(cob_raw))
                mapping: list[MapEntry] = []
                count = self.value(map_base + n, 0, node) or 0
                for sub in range(1, int(count) + 1):
                    word = self.value(map_base + n, sub, node)
                    if word:
                        mapping.extend(self.map_entries(*split_mapping_word(int(word)), context))
                out.append(
                    PdoConfig(
                        direction=direction,
                        number=n + 1,
                        cob_id=cob_id,
                        valid=valid,
                        transmission_type=_int_or(self.value(comm_base + n, 2, node), 255),
                        inhibit_time=int(self.value(comm_base + n, 3, node) or 0),
                        event_timer=int(self.value(comm_base + n, 5, node) or 0),
                        mapping=mapping,
                    )
                )
        return out

    # --- EMCY ----------------------------------------------------------------
    def decode_emcy(self, error_code: int, register: int, manufacturer: bytes) -> dict | None:
        """The record's `manufacturer_decoded` field, or None when the profile has no table."""
        if self.sidecar is None or self.sidecar.emcy is None:
            return None
        return self.sidecar.emcy.decode(error_code, register, bytes(manufacturer))


def _int_or(value, default: int) -> int:
    """An object's integer value, or `default` when the dictionary gives none (255 for a
    missing transmission type: see node_config.UNKNOWN_TYPE)."""
    return value if isinstance(value, int) and not isinstance(value, bool) else default


def build_profile(path: Path, sidecar: Sidecar | None, node_id: int | None) -> DeviceProfile:
    facts, od = load_facts(path, node_id, read_od)
    info = facts.info
    prof = DeviceProfile(  # the file's texts and name, as a terminal may show them
        key=printable(sidecar.key if sidecar else path.stem),
        name=printable((sidecar.name if sidecar else "") or info["product_name"] or path.stem),
        vendor_id=None,
        product_code=None,
        device_type=None,
        device_name=None,
        notes=list(sidecar.notes) if sidecar else [],
        source=str(path),
        facts=facts,
        sidecar=sidecar,
        node_id=facts.node_id or node_id,
        parsed=od,
        load_od=partial(read_od, path, node_id),
    )

    def od_value(index: int, sub: int):  # as the file says it, $NODEID unresolved
        var = prof._variable(index, sub)
        return effective_value(var, None) if var is not None else None

    def od_int(index: int, sub: int) -> int | None:
        value = od_value(index, sub)
        return value if isinstance(value, int) else None

    def od_str(index: int) -> str | None:
        value = od_value(index, 0)
        return value if isinstance(value, str) and value else None

    prof.vendor_id = od_int(0x1018, 1) or info["vendor_number"]
    prof.product_code = od_int(0x1018, 2) or info["product_number"]
    prof.device_type = od_int(0x1000, 0)
    prof.device_name = printable_or_none(od_str(0x1008) or info["product_name"])
    return prof


def load_eds(path: str | Path, node_id: int | None = None) -> DeviceProfile:
    """Profile from any EDS/DCF; a DCF's ParameterValues take precedence over defaults.

    A TOML sidecar of the same name beside it (`drive.eds` + `drive.toml`, the format of
    `decoders/*.toml`) is the user's own units, scales, bit names and EMCY meanings."""
    path = Path(path)
    side = path.with_suffix(".toml")
    return build_profile(path, load_sidecar(side) if side.is_file() else None, node_id)
