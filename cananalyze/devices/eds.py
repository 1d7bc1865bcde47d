"""Reading EDS/DCF files through `canopen.objectdictionary.import_od`, and XDD/XDC.

canopen parses CiA 306 well (compact sub-objects, $NODEID, DCF ParameterValue);
this module only turns its exceptions into one-line InputErrors and answers the
few questions the profile asks: an object's description and its effective value.
CiA 311 XDD/XDC files (XML) are read by `xdd.py` into the same ObjectDictionary, here,
the one place a device file is loaded.
"""

from __future__ import annotations

import logging
import re
from configparser import Error as ConfigParserError
from dataclasses import dataclass
from pathlib import Path

from cananalyze.core.errors import InputError
from cananalyze.core.text import printable


@dataclass(frozen=True)
class ObjectInfo:
    """What the object dictionary says about one (index, subindex)."""

    index: int
    subindex: int
    name: str
    datatype: int
    default: int | float | str | bytes | None  # DCF ParameterValue if given, else DefaultValue
    pdo_mappable: bool = False


# .xpd: CANopenEditor's project file, an XDD with CANopenNode's own properties added
DEVICE_SUFFIXES = (".eds", ".dcf", ".xdd", ".xdc", ".xpd")


def read_od(path: str | Path, node_id: int | None = None):
    """canopen ObjectDictionary of an EDS/DCF/XDD/XDC, or InputError naming the file and
    the problem. XML content (a CiA 311 XDD/XDC) is read as such whatever the suffix."""
    from canopen.objectdictionary import import_od

    from cananalyze.devices.xdd import looks_like_xml, read_xdd, signed_hex

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such EDS/DCF/XDD/XDC file")
    if path.suffix.lower() not in DEVICE_SUFFIXES:
        raise InputError(
            f"{path}: not an EDS, DCF, XDD or XDC file (expected .eds, .dcf, .xdd, .xdc or .xpd)"
        )
    if path.suffix.lower() in (".xdd", ".xdc", ".xpd") or looks_like_xml(path):
        od = read_xdd(path, node_id)
        if len(od) == 0:
            raise InputError(f"{path}: XDD/XDC holds no objects")
        return od
    # canopen logs warnings for every odd entry of vendor files; they are not ours to show.
    logger = logging.getLogger("canopen.objectdictionary.eds")
    level = logger.level
    logger.setLevel(logging.ERROR)
    try:
        try:
            od = import_od(str(path), node_id)
        except ValueError:
            # canopen stops at an empty number in [DeviceInfo] (CANopenNode's DS301 profile
            # EDS ships `VendorNumber=`); read it again without the empty entries, which
            # canopen then passes over as absent. Any other fault fails again, below.
            od = _without_empty_device_info(path, node_id)
    except (ConfigParserError, UnicodeDecodeError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"{path}: not a valid EDS/DCF: {msg}") from None
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise InputError(f"{path}: not a valid EDS/DCF: {type(exc).__name__}: {exc}") from None
    finally:
        logger.setLevel(level)
    if len(od) == 0:
        raise InputError(f"{path}: EDS/DCF holds no objects")
    for entry in od.values():
        for var in entry.subindices.values() if hasattr(entry, "subindices") else [entry]:
            for raw_attr, attr in (("default_raw", "default"), ("value_raw", "value")):
                raw, number = getattr(var, raw_attr, None), getattr(var, attr, None)
                if isinstance(raw, str) and type(number) is int:
                    setattr(var, attr, signed_hex(var.data_type, raw, number))
    return od


def _without_empty_device_info(path: Path, node_id: int | None):
    import io

    from canopen.objectdictionary.eds import import_eds

    lines, section = [], ""
    with open(path) as f:  # as canopen opens it
        for line in f:
            stripped = line.strip()
            if stripped.startswith("["):
                section = stripped.lower()
            elif section == "[deviceinfo]" and re.fullmatch(r"[^=;]+=\s*", stripped):
                continue
            lines.append(line)
    return import_eds(io.StringIO("".join(lines)), node_id)


_NODEID = re.compile(r"\+?\$NODEID\+?", re.IGNORECASE)


def resolve_raw(raw: str | None, node_id: int | None) -> int | None:
    """Integer value of a DefaultValue/ParameterValue string that may hold $NODEID."""
    if raw is None:
        return None
    text = raw.replace(" ", "")
    try:
        if "$NODEID" in text.upper():
            if node_id is None:
                return None
            rest = _NODEID.sub("", text)
            return (int(rest, 0) if rest else 0) + node_id
        return int(text, 0)
    except ValueError:
        return None


def effective_value(var, node_id: int | None) -> int | float | str | bytes | None:
    """DCF ParameterValue if present, else DefaultValue, with $NODEID resolved for node_id."""
    for raw_attr, attr in (("value_raw", "value"), ("default_raw", "default")):
        raw = getattr(var, raw_attr, None)
        if raw is None:
            continue
        if isinstance(raw, str) and "$NODEID" in raw.upper():
            return resolve_raw(raw, node_id)
        value = getattr(var, attr, None)
        if value is not None:
            return value
    return None


def variable(od, index: int, subindex: int):
    """The canopen ODVariable at (index, subindex), or None.

    Absent objects are answered from canopen's dicts first: its KeyError path
    formats a message, and building a node's configuration asks for ~1000 of them.
    """
    indices = getattr(od, "indices", None)
    if type(index) is int and isinstance(indices, dict):
        if index not in indices and index not in od.names:
            return None
    try:
        entry = od[index]
    except KeyError:
        return None
    subs = getattr(entry, "subindices", None)
    if (
        type(entry).__name__ == "ODRecord"
        and type(subindex) is int
        and isinstance(subs, dict)
        and subindex not in subs
        and subindex not in entry.names
    ):
        return None  # a record has no template for missing sub-indices (an array has)
    if hasattr(entry, "subindices"):
        try:
            return entry[subindex]
        except KeyError:
            return None
    return entry if subindex == 0 else None


def object_info(od, index: int, subindex: int, node_id: int | None) -> ObjectInfo | None:
    return info_of(variable(od, index, subindex), index, subindex, node_id)


def info_of(var, index: int, subindex: int, node_id: int | None) -> ObjectInfo | None:
    """ObjectInfo of a canopen ODVariable (or `od_facts.Var`: the same attributes)."""
    if var is None:
        return None
    return ObjectInfo(
        index=index,
        subindex=subindex,
        name=printable(var.name),  # an EDS's text: shown on terminals
        datatype=int(var.data_type or 0),
        default=effective_value(var, node_id),
        pdo_mappable=bool(var.pdo_mappable),
    )
