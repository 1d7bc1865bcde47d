"""CiA 301 communication-profile objects every device shares (0x1000-0x1FFF).

Names and data types for SDO values when no device profile or EDS is known:
a read of 0x1018:01 is a vendor-ID on every CANopen device.
"""

from __future__ import annotations

from cananalyze.protocol.mpdo import object_name as mpdo_object
from cananalyze.protocol.srdo import object_name as srdo_object

U8, U16, U32, VSTR = 0x05, 0x06, 0x07, 0x09

# index -> (name, {subindex: (name, type)} or the type of every subindex >= 1)
_FIXED: dict[int, tuple[str, int]] = {
    0x1000: ("Device type", U32),
    0x1001: ("Error register", U8),
    0x1002: ("Manufacturer status register", U32),
    0x1005: ("COB-ID SYNC", U32),
    0x1006: ("Communication cycle period", U32),
    0x1007: ("Synchronous window length", U32),
    0x1008: ("Manufacturer device name", VSTR),
    0x1009: ("Manufacturer hardware version", VSTR),
    0x100A: ("Manufacturer software version", VSTR),
    0x100C: ("Guard time", U16),
    0x100D: ("Life time factor", U8),
    0x1012: ("COB-ID time stamp", U32),
    0x1014: ("COB-ID EMCY", U32),
    0x1015: ("Inhibit time EMCY", U16),
    0x1017: ("Producer heartbeat time", U16),
    0x1019: ("Synchronous counter overflow value", U8),
}

_RECORDS: dict[int, tuple[str, dict[int, tuple[str, int]]]] = {
    0x1003: ("Pre-defined error field", {0: ("Number of errors", U8)}),
    0x1010: ("Store parameters", {0: ("Highest sub-index supported", U8)}),
    0x1011: ("Restore default parameters", {0: ("Highest sub-index supported", U8)}),
    0x1016: ("Consumer heartbeat time", {0: ("Highest sub-index supported", U8)}),
    0x1018: (
        "Identity object",
        {
            0: ("Highest sub-index supported", U8),
            1: ("Vendor-ID", U32),
            2: ("Product code", U32),
            3: ("Revision number", U32),
            4: ("Serial number", U32),
        },
    ),
}
_RECORD_DEFAULT = {0x1003: U32, 0x1010: U32, 0x1011: U32, 0x1016: U32}

_PDO_COMM = {
    0: ("Highest sub-index supported", U8),
    1: ("COB-ID", U32),
    2: ("Transmission type", U8),
    3: ("Inhibit time", U16),
    4: ("Reserved", U8),
    5: ("Event timer", U16),
    6: ("SYNC start value", U8),
}
_SDO_PARAM = {
    0: ("Highest sub-index supported", U8),
    1: ("COB-ID client->server", U32),
    2: ("COB-ID server->client", U32),
    3: ("Node-ID of the SDO client/server", U8),
}


def comm_object(index: int, subindex: int) -> tuple[str, int] | None:
    """(name, CiA 301 data type) of a communication-profile object, or None."""
    if index in _FIXED:
        return _FIXED[index]
    if index in _RECORDS:
        name, subs = _RECORDS[index]
        if subindex in subs:
            return f"{name}: {subs[subindex][0]}", subs[subindex][1]
        if index in _RECORD_DEFAULT and subindex >= 1:
            return f"{name} {subindex}", _RECORD_DEFAULT[index]
        return None
    if 0x1200 <= index <= 0x12FF and subindex in _SDO_PARAM:
        kind = "Server" if index < 0x1280 else "Client"
        name, dtype = _SDO_PARAM[subindex]
        return f"{kind} SDO parameter {index & 0x7F:d}: {name}", dtype
    for base, label in ((0x1400, "RPDO"), (0x1800, "TPDO")):
        if base <= index <= base + 0x1FF and subindex in _PDO_COMM:
            name, dtype = _PDO_COMM[subindex]
            return f"{label}{index - base + 1} communication: {name}", dtype
    for base, label in ((0x1600, "RPDO"), (0x1A00, "TPDO")):
        if base <= index <= base + 0x1FF:
            if subindex == 0:
                return f"{label}{index - base + 1} mapping: number of entries", U8
            return f"{label}{index - base + 1} mapping: entry {subindex}", U32
    return srdo_object(index, subindex) or mpdo_object(index, subindex)  # 0x13xx, 0x1FA0+
