"""Configuration objects in words: what an SDO read or write of a CiA 301 object means.

`object_words(index, subindex, value, data, name_of)` gives "node 5, 1000 ms" for a
0x1016 entry, "COB-ID 0x181, valid, RTR allowed, 11-bit" for a PDO COB-ID, "6041:00,
16 bit, Statusword" for a mapping entry, an inhibit time in ms, 0x1000 as its profile and
type bits, 0x1018 as identity; a CiA 402 statusword, controlword or mode by name (when
the node's dictionary names the object so); and data of an unknown type that reads as a
VISIBLE_STRING as that text. None when there is nothing to add to the number.
"""

from __future__ import annotations

import re
from collections.abc import Callable

from cananalyze.devices import cia402

NameOf = Callable[[int, int], str | None]  # (index, subindex) -> the node's name for it

PROFILES = {
    301: "CiA 301 (no device profile)",
    401: "CiA 401 generic I/O",
    402: "CiA 402 drives and motion control",
    404: "CiA 404 measuring devices",
    405: "CiA 405 IEC 61131-3 programmable devices",
    406: "CiA 406 encoders",
    408: "CiA 408 hydraulic drives",
    410: "CiA 410 inclinometers",
    418: "CiA 418 battery modules",
    419: "CiA 419 battery chargers",
    443: "CiA 443 SIIS level-2 devices",
    447: "CiA 447 car add-on devices",
}
_401_BITS = ((0, "digital input"), (1, "digital output"), (2, "analog input"), (3, "analog output"))
TRANSMISSION = {
    0: "synchronous, acyclic",
    252: "RTR only, synchronous",
    253: "RTR only, event-driven",
    254: "event-driven (manufacturer-specific)",
    255: "event-driven (device profile)",
}
_NAMES_WITH_WORDS = {
    "statusword": cia402.STATUSWORD,
    "controlword": cia402.CONTROLWORD,
    "modesofoperation": cia402.MODES,
    "modesofoperationdisplay": cia402.MODES_DISPLAY,
}


def _ms(units_100us: int) -> str:
    return f"{units_100us / 10:g} ms"


def device_type_words(value: int) -> str:
    profile, extra = value & 0xFFFF, (value >> 16) & 0xFFFF
    text = f"profile {PROFILES.get(profile, f'CiA {profile}')}"
    if profile == 401:
        io = [name for bit, name in _401_BITS if extra >> bit & 1]
        return f"{text}, {', '.join(io) or 'no I/O bits'} (0x{extra:04X})"
    return f"{text}, additional information 0x{extra:04X}"


def cob_id_words(value: int, rtr_bit: bool = True, valid_bit: bool = True) -> str:
    """A PDO/EMCY/SDO COB-ID entry: identifier and flag bits."""
    ext = bool(value & 0x20000000)
    ident = value & (0x1FFFFFFF if ext else 0x7FF)
    parts = [f"COB-ID 0x{ident:0{8 if ext else 3}X}"]
    if valid_bit:
        parts.append("not valid" if value & 0x80000000 else "valid")
    if rtr_bit:
        parts.append("no RTR" if value & 0x40000000 else "RTR allowed")
    parts.append("29-bit" if ext else "11-bit")
    return ", ".join(parts)


def mapping_words(value: int, name_of: NameOf | None) -> str:
    index, sub, bits = (value >> 16) & 0xFFFF, (value >> 8) & 0xFF, value & 0xFF
    if value == 0:
        return "empty"
    name = name_of(index, sub) if name_of is not None else None
    if name is None and 1 <= index <= 7:
        name = "dummy"
    return f"{index:04X}:{sub:02X}, {bits} bit" + (f", {name}" if name else "")


def _pdo_words(index: int, sub: int, value: int, name_of: NameOf | None) -> str | None:
    if 0x1400 <= index <= 0x15FF or 0x1800 <= index <= 0x19FF:
        if sub == 1:
            return cob_id_words(value)
        if sub == 2:
            if 1 <= value <= 240:
                return (
                    f"synchronous, every {value} SYNC" if value > 1 else "synchronous, every SYNC"
                )
            return TRANSMISSION.get(value, "reserved")
        if sub == 3:
            return f"inhibit time {_ms(value)}"
        if sub == 5:
            return f"event timer {value} ms" if value else "event timer off"
        if sub == 6:
            return f"SYNC start value {value}"
        return None
    if sub == 0:
        return f"{value} entries mapped" if value != 1 else "1 entry mapped"
    return mapping_words(value, name_of)


def config_words(index: int, sub: int, value: int, name_of: NameOf | None = None) -> str | None:
    """Words for a CiA 301 communication object's integer value, or None."""
    if index == 0x1000:
        return device_type_words(value)
    if index == 0x1001:
        return None
    if index == 0x1005:
        gen = "generates SYNC" if value & 0x40000000 else "consumes SYNC"
        return f"{cob_id_words(value, rtr_bit=False, valid_bit=False)}, {gen}"
    if index in (0x1006, 0x1007):
        return f"{value} us" if value else "off"
    if index == 0x100C:
        return f"{value} ms" if value else "off"
    if index == 0x1012:
        flags = [f for bit, f in ((31, "consumes TIME"), (30, "produces TIME")) if value >> bit & 1]
        return cob_id_words(value, rtr_bit=False, valid_bit=False) + (
            f", {', '.join(flags)}" if flags else ""
        )
    if index == 0x1014:
        return cob_id_words(value, rtr_bit=False)
    if index == 0x1015:
        return _ms(value) if value else "off"
    if index == 0x1016 and sub >= 1:
        node, ms = (value >> 16) & 0xFF, value & 0xFFFF
        return f"node {node}, {ms} ms" if node and ms else "not used"
    if index == 0x1017:
        return f"{value} ms" if value else "off"
    if index == 0x1018:  # vendor-ID, product code, serial: the number says it all
        return f"revision {value >> 16}.{value & 0xFFFF}" if sub == 3 else None
    if 0x1200 <= index <= 0x12FF and sub in (1, 2):
        return cob_id_words(value, rtr_bit=False)
    if 0x1400 <= index <= 0x1BFF and (index & 0x1FF) < 0x200:
        return _pdo_words(index, sub, value, name_of)
    return None


_PRINTABLE = re.compile(rb"[\x20-\x7e]+\x00*")


def visible_string(data: bytes) -> str | None:
    """Data of an unknown type that reads as text: more than 4 bytes (a segmented or
    block transfer: one in 50 random 4-byte values is printable, so expedited process
    data is never guessed to be text), printable ASCII with a letter, then only NULs."""
    if len(data) > 4 and _PRINTABLE.fullmatch(data):
        text = data.rstrip(b"\0").decode("ascii")
        if len(text) >= 2 and any(c.isalpha() for c in text):
            return f'text "{text}"'
    return None


def _norm(name: str | None) -> str:
    return re.sub(r"[^0-9a-z]", "", (name or "").lower())


def object_words(
    index: int | None,
    sub: int | None,
    value,
    data: bytes | None,
    name: str | None = None,
    name_of: NameOf | None = None,
) -> str | None:
    """The words of one SDO transfer's value (None: none to add)."""
    if not isinstance(index, int) or not isinstance(sub, int):
        return None
    ivalue = value if isinstance(value, int) and not isinstance(value, bool) else None
    if ivalue is None and value is None and data and len(data) <= 8 and 0x1000 <= index <= 0x1FFF:
        ivalue = int.from_bytes(data, "little")
    if ivalue is not None:
        if 0x1000 <= index <= 0x1FFF:
            return config_words(index, sub, ivalue & 0xFFFFFFFF, name_of)
        worded = _NAMES_WITH_WORDS.get(_norm(name))
        if worded == index and sub == 0:
            from cananalyze.devices.words import word

            return word(index, ivalue)
    if value is None and data:
        return visible_string(data)
    return None
