"""Which CiA 4xx profile a device type (0x1000) names, and that profile's object units:
the CiA 401/402 tables read by key, for the profiles, the network model and the outputs."""

from __future__ import annotations

from cananalyze.devices import cia401, cia402

FAMILIES = {402: cia402, 401: cia401}
KEYS = {"cia402": 402, "cia401": 401}


def family(device_type: int | None) -> int | None:
    """402 or 401 when a device type value (0x1000) names one of these profiles."""
    if not isinstance(device_type, int) or isinstance(device_type, bool):
        return None
    profile = device_type & 0xFFFF
    return profile if profile in FAMILIES else None


def object_unit(profile: int | None, index: int, subindex: int) -> str | None:
    """The profile's unit of an object (None: none, or not a profile object)."""
    table = FAMILIES.get(profile) if profile else None
    entry = table.OBJECTS.get((index, subindex)) if table else None
    return entry[2] if entry else None
