"""The simulated node's object dictionary: raw values per (index, subindex).

Built from a DeviceProfile's canopen ObjectDictionary so any EDS works. Values
are kept as encoded bytes, which is what SDO and PDO move; the typed accessors
exist for the node's own logic (NMT, heartbeat, PDO parameters, signals).
"""

from __future__ import annotations

from cananalyze.devices.profile import DeviceProfile
from cananalyze.protocol.sdo import (
    ABORT_NO_OBJECT,
    ABORT_NO_SUBINDEX,
    ABORT_READ_ONLY,
    ABORT_TOO_LONG,
    ABORT_TOO_SHORT,
    ABORT_WRITE_ONLY,
)

# CiA 301 integer data types: little-endian, fixed size; read without canopen's codec
# because the node reads PDO parameters on every input scan.
_SIGNED = {0x02, 0x03, 0x04, 0x10, 0x12, 0x13, 0x14, 0x15}
_UNSIGNED = {0x01, 0x05, 0x06, 0x07, 0x16, 0x18, 0x19, 0x1A, 0x1B}


class SdoAbort(Exception):
    """An access the object dictionary refuses, with its CiA 301 abort code."""

    def __init__(self, code: int):
        super().__init__(f"SDO abort 0x{code:08X}")
        self.code = code


class Dictionary:
    """Encoded values and access rights of every object of one node."""

    def __init__(
        self, profile: DeviceProfile, node_id: int, config: list[tuple[int, int, int]] = ()
    ):
        self.profile = profile
        self.node_id = node_id
        self.config = list(config)  # stored parameters (index, subindex, value) over defaults
        self.values: dict[tuple[int, int], bytes] = {}
        self.vars: dict[tuple[int, int], object] = {}
        self.indices: set[int] = set()
        self.reset()

    def reset(self, communication_only: bool = False) -> None:
        """Defaults from the EDS/DCF (reset node), or only 0x1000-0x1FFF (reset communication)."""
        import canopen.objectdictionary as cod

        for obj in self.profile.od.values():
            self.indices.add(obj.index)
            if isinstance(obj, cod.ODVariable):
                members = [obj]
            else:
                members = list(obj.values())
            for var in members:
                key = (obj.index, var.subindex)
                if communication_only and not 0x1000 <= obj.index < 0x2000:
                    continue
                self.vars[key] = var
                self.values[key] = self._default(var)
        for index, subindex, value in self.config:
            if communication_only and not 0x1000 <= index < 0x2000:
                continue
            if (index, subindex) not in self.vars:
                self._declare(index, subindex)
            self.set(index, subindex, value)

    def _declare(self, index: int, subindex: int) -> None:
        """A stored parameter the profile lacks (a network file's SRDO or MPDO lists on a
        device whose EDS has none, or a DAM-MPDO's mapping entry on a PDO the EDS maps
        nothing in), typed as the analyser types them (protocol/srdo.py, protocol/mpdo.py,
        protocol/comm_objects.py); other objects the profile lacks stay absent, as before."""
        import canopen.objectdictionary as cod

        from cananalyze.protocol import mpdo, srdo
        from cananalyze.protocol.comm_objects import comm_object

        found = srdo.object_name(index, subindex) or mpdo.object_name(index, subindex)
        is_mapping = 0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00
        if found is None and is_mapping and index in self.indices:
            found = comm_object(index, subindex)
        if found is None:
            return
        var = cod.ODVariable(found[0], index, subindex)
        var.data_type, var.access_type = found[1], "rw"
        self.indices.add(index)
        self.vars[(index, subindex)] = var
        self.values[(index, subindex)] = bytes(var.encode_raw(0))

    def _default(self, var) -> bytes:
        value = self.profile.value(var.index, var.subindex, self.node_id)
        if value is None:
            value = "" if var.data_type in (0x09, 0x0A, 0x0B, 0x0F) else 0
        try:
            return bytes(var.encode_raw(value))
        except (TypeError, ValueError, AttributeError):
            return b""

    def _var(self, index: int, subindex: int):
        var = self.vars.get((index, subindex))
        if var is None:
            raise SdoAbort(ABORT_NO_SUBINDEX if index in self.indices else ABORT_NO_OBJECT)
        return var

    # --- SDO side: checked access ------------------------------------------------
    def read(self, index: int, subindex: int) -> bytes:
        var = self._var(index, subindex)
        if var.access_type == "wo":
            raise SdoAbort(ABORT_WRITE_ONLY)
        return self.values[(index, subindex)]

    def check_write(self, index: int, subindex: int):
        """The object's variable if it exists and is writable, else SdoAbort."""
        var = self._var(index, subindex)
        if var.access_type in ("ro", "const"):
            raise SdoAbort(ABORT_READ_ONLY)
        return var

    def write(self, index: int, subindex: int, data: bytes) -> None:
        var = self.check_write(index, subindex)
        fixed = len(self.values[(index, subindex)]) if var.fixed_size else None
        if fixed is not None and len(data) != fixed:
            raise SdoAbort(ABORT_TOO_LONG if len(data) > fixed else ABORT_TOO_SHORT)
        self.values[(index, subindex)] = bytes(data)

    # --- device side: unchecked typed access ---------------------------------------
    def has(self, index: int, subindex: int) -> bool:
        return (index, subindex) in self.values

    def get(self, index: int, subindex: int, default: int = 0) -> int:
        raw = self.values.get((index, subindex))
        if raw is None or not raw:
            return default
        var = self.vars[(index, subindex)]
        if var.data_type in _UNSIGNED:
            return int.from_bytes(raw, "little")
        if var.data_type in _SIGNED:
            return int.from_bytes(raw, "little", signed=True)
        try:
            value = var.decode_raw(raw)
        except (ValueError, TypeError):
            return default
        return value if isinstance(value, int) else default

    def set(self, index: int, subindex: int, value: int) -> None:
        var = self.vars.get((index, subindex))
        if var is None:
            return
        old = self.values[(index, subindex)]
        if old and (var.data_type in _UNSIGNED or var.data_type in _SIGNED):
            bits = 8 * len(old)
            self.values[(index, subindex)] = (value & ((1 << bits) - 1)).to_bytes(
                len(old), "little"
            )
            return
        self.values[(index, subindex)] = bytes(var.encode_raw(value))

    def set_raw(self, index: int, subindex: int, raw: bytes) -> None:
        if (index, subindex) in self.values:
            self.values[(index, subindex)] = bytes(raw)
