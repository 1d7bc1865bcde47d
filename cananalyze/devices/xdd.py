"""Reading CiA 311 XDD (device description) and XDC (configured device) files.

The XML counterpart of an EDS/DCF becomes the same `canopen.objectdictionary.ObjectDictionary`
that `import_od` builds from an EDS (names, data types, access, defaults, limits, PDO
mapping flags, device information), so everything that reads a profile is unchanged. An
XDC's `actualValue` is what a DCF's `ParameterValue` is (`value_raw`/`value`), and its
`deviceCommissioning nodeID` what a DCF's `[DeviceComissioning] NodeID` is.

The file is hostile input: defusedxml refuses any DTD (so entity expansion and external
entities too), the file is read to at most MAX_BYTES and its elements nested at most
MAX_DEPTH deep; each refusal is one InputError line naming the file.

Both places CiA 311 lets a file put an object's description are read: attributes of the
`CANopenObject`/`CANopenSubObject` itself (dataType, accessType, defaultValue, actualValue,
lowLimit, highLimit), and the `parameter` of the ApplicationProcess that its `uniqueIDRef`
names (an IEC 61131 type element, `access`, `defaultValue`, `actualValue`, `allowedValues`),
as CANopenEditor writes them. The object's own attribute wins where both are given.
"""

from __future__ import annotations

import io
import re
from pathlib import Path
from xml.etree.ElementTree import Element, ParseError

from cananalyze.core.errors import InputError, read_bounded

MAX_BYTES = 32 << 20  # the largest vendor XDDs are a few MiB; /dev/zero stops here
MAX_DEPTH = 64  # CiA 311 files nest about 10 deep; a 100k-deep file is refused early

VAR, DOMAIN_OBJECT, ARR, RECORD = 7, 2, 8, 9

# IEC 61131-3 element of a `parameter` -> CANopen data type (CiA 311; BYTE/WORD/... as
# unsigned, CHAR as INTEGER8, as CANopenEditor reads them). BITSTRING is an OCTET_STRING
# with a default and a DOMAIN without one.
IEC_TYPES = {
    "BOOL": 0x01,
    "SINT": 0x02,
    "CHAR": 0x02,
    "INT": 0x03,
    "DINT": 0x04,
    "LINT": 0x15,
    "USINT": 0x05,
    "BYTE": 0x05,
    "UINT": 0x06,
    "WORD": 0x06,
    "UDINT": 0x07,
    "DWORD": 0x07,
    "ULINT": 0x1B,
    "LWORD": 0x1B,
    "REAL": 0x08,
    "LREAL": 0x11,
    "STRING": 0x09,
    "WSTRING": 0x0B,
}
OCTET_STRING, DOMAIN = 0x0A, 0x0F
# `parameter access` -> EDS AccessType ("read" is the schema's default)
ACCESS = {
    "const": "const",
    "read": "ro",
    "write": "wo",
    "readWrite": "rw",
    "readWriteInput": "rwr",
    "readWriteOutput": "rww",
    "noAccess": "const",
}
EDS_ACCESS = {"ro", "wo", "rw", "rwr", "rww", "const"}


def looks_like_xml(path: Path) -> bool:
    """True when the file's first non-blank byte (after a UTF-8 BOM) is '<'."""
    try:
        with open(path, "rb") as f:
            head = f.read(256)
    except OSError:
        return False
    return head.removeprefix(b"\xef\xbb\xbf").lstrip()[:1] == b"<"


def read_xdd(path: str | Path, node_id: int | None = None):
    """canopen ObjectDictionary of an XDD/XDC, or InputError naming the file and the problem."""
    path = Path(path)
    root = parse(path)
    try:
        return _build(root, node_id, path)
    except (ValueError, TypeError, KeyError, IndexError) as exc:
        raise InputError(f"{path}: not a valid XDD/XDC: {type(exc).__name__}: {exc}") from None


def parse(path: Path) -> Element:
    """The root element, parsed safely (see the module's docstring)."""
    from defusedxml import DTDForbidden, EntitiesForbidden, ExternalReferenceForbidden
    from defusedxml.ElementTree import iterparse

    data = read_bounded(path, MAX_BYTES, "XDD/XDC", "refused: an XDD/XDC larger than")
    root = None
    depth = 0
    try:
        for event, elem in iterparse(io.BytesIO(data), events=("start", "end"), forbid_dtd=True):
            if event == "end":
                depth -= 1
                continue
            depth += 1
            if root is None:
                root = elem
            if depth > MAX_DEPTH:
                raise InputError(f"{path}: refused: XML elements nested more than {MAX_DEPTH} deep")
    except (DTDForbidden, EntitiesForbidden, ExternalReferenceForbidden):
        raise InputError(
            f"{path}: refused: the XML declares a DTD or entities (<!DOCTYPE>, <!ENTITY>), "
            "which an XDD/XDC never needs"
        ) from None
    except (ParseError, LookupError) as exc:  # LookupError: an unknown declared encoding
        raise InputError(f"{path}: not a valid XDD/XDC: XML {exc}") from None
    if root is None:
        raise InputError(f"{path}: not a valid XDD/XDC: no XML element")
    return root


def _local(elem: Element) -> str:
    tag = elem.tag if isinstance(elem.tag, str) else ""
    return tag.rsplit("}", 1)[-1]


def _children(elem: Element, name: str) -> list[Element]:
    return [c for c in elem if _local(c) == name]


def _child(elem: Element | None, name: str) -> Element | None:
    if elem is None:
        return None
    return next((c for c in elem if _local(c) == name), None)


def _first(root: Element, name: str) -> Element | None:
    return next((e for e in root.iter() if _local(e) == name), None)


def _int(text: str | None) -> int | None:
    try:
        return int(str(text).strip(), 0)
    except (TypeError, ValueError):
        return None


def _build(root: Element, node_id: int | None, path: Path):
    from canopen import objectdictionary as odmod

    if _local(root) != "ISO15745ProfileContainer":
        raise InputError(
            f"{path}: not a valid XDD/XDC: the root element is <{_local(root)}>, "
            "not <ISO15745ProfileContainer>"
        )
    object_list = _first(root, "CANopenObjectList")
    if object_list is None:
        raise InputError(f"{path}: not a valid XDD/XDC: no CANopenObjectList")
    params = {
        e.get("uniqueID"): e
        for e in root.iter()
        if _local(e) == "parameter" and e.get("uniqueID") is not None
    }
    od = odmod.ObjectDictionary()
    commissioning = next(
        (e for e in root.iter() if _local(e).lower() == "devicecommissioning"), None
    )
    if commissioning is not None:
        if node_id is None:
            node_id = _int(commissioning.get("nodeID") or commissioning.get("NodeID"))
            if node_id is not None and not 1 <= node_id <= 127:
                node_id = None  # vendor tools write nodeID="0" for a device not commissioned
        od.node_id = node_id
        od.bitrate = _bitrate(commissioning.get("actualBaudRate"))
    _device_information(od, root)

    for obj in _children(object_list, "CANopenObject"):
        index = int(obj.get("index", ""), 16)
        name = obj.get("name") or _label(params.get(obj.get("uniqueIDRef"))) or f"{index:04X}"
        otype = _int(obj.get("objectType")) or VAR
        if _disabled(params.get(obj.get("uniqueIDRef"))):
            continue
        if otype in (VAR, DOMAIN_OBJECT):
            od.add_object(_variable(obj, params, node_id, name, index, 0))
        elif otype in (ARR, RECORD):
            entry = odmod.ODArray(name, index) if otype == ARR else odmod.ODRecord(name, index)
            for sub in _children(obj, "CANopenSubObject"):
                subindex = int(sub.get("subIndex", ""), 16)
                sub_name = sub.get("name") or _label(params.get(sub.get("uniqueIDRef")))
                entry.add_member(_variable(sub, params, node_id, sub_name or "", index, subindex))
            od.add_object(entry)
        # other object types (DEFTYPE, DEFSTRUCT) are skipped, as import_od skips them

    dummies = _first(root, "dummyUsage")
    for dummy in _children(dummies, "dummy") if dummies is not None else []:
        m = re.fullmatch(r"\s*Dummy(\d{4})\s*=\s*([01])\s*", dummy.get("entry") or "")
        if m and m.group(2) == "1" and 1 <= int(m.group(1)) <= 7 and int(m.group(1)) not in od:
            var = odmod.ODVariable(f"Dummy{m.group(1)}", int(m.group(1)), 0)
            var.data_type = int(m.group(1))
            var.access_type = "const"
            od.add_object(var)
    return od


def _bitrate(text: str | None) -> int | None:
    """bit/s of an `actualBaudRate`: CiA 311 writes "250 Kbps", FAULHABER Motion Manager a
    bare kbit/s number ("125"), maxon's EPOS Studio bit/s ("1000000"); "auto-baudRate" and
    anything else is no rate."""
    m = re.fullmatch(r"\s*(\d+)\s*([kKmM]?)(?:bps|bit/s|Bd|baud)?\s*", text or "")
    if not m:
        return None
    value, unit = int(m.group(1)), m.group(2).lower()
    if unit == "m":
        return value * 1_000_000
    if unit == "k" or value < 10_000:  # CAN's lowest rate is 10 kbit/s = 10000 bit/s
        return value * 1000
    return value


def _disabled(param: Element | None) -> bool:
    """CANopenEditor's own `CO_disabled` property: the object is not in the device (its EDS
    export leaves it out, and so do we)."""
    return param is not None and any(
        _local(p) == "property" and p.get("name") == "CO_disabled" and p.get("value") == "true"
        for p in param
    )


def _label(param: Element | None) -> str | None:
    label = _child(param, "label")
    return label.text.strip() if label is not None and label.text else None


def _device_information(od, root: Element) -> None:
    info = od.device_information
    identity = _first(root, "DeviceIdentity")
    if identity is not None:
        for tag, attr, conv in (
            ("vendorName", "vendor_name", str),
            ("vendorID", "vendor_number", _int),
            ("productName", "product_name", str),
            ("productID", "product_number", _int),
        ):
            elem = _child(identity, tag)
            text = (elem.text or "").strip() if elem is not None else ""
            if text and conv(text) is not None:
                setattr(info, attr, conv(text))
    for rate in (e for e in root.iter() if _local(e) == "supportedBaudRate"):
        m = re.match(r"\s*(\d+)\s*Kbps", rate.get("value") or "", re.IGNORECASE)
        if m:
            info.allowed_baudrates.add(int(m.group(1)) * 1000)
    features = _first(root, "CANopenGeneralFeatures")
    if features is not None:
        for key, attr in (("nrOfRxPDO", "nr_of_RXPDO"), ("nrOfTxPDO", "nr_of_TXPDO")):
            if _int(features.get(key)) is not None:
                setattr(info, attr, _int(features.get(key)))
        # the schema's default is "false", as an EDS's LSS_Supported=0 (Elcom's e-RIO XDD
        # leaves the attribute out where its EDS says 0)
        info.LSS_supported = features.get("layerSettingServiceSlave", "false") in ("true", "1")


def _param_value(param: Element | None, tag: str) -> str | None:
    elem = _child(param, tag)
    return elem.get("value") if elem is not None else None


def _variable(obj: Element, params: dict, node_id: int | None, name: str, index, subindex):
    from canopen import objectdictionary as odmod

    param = params.get(obj.get("uniqueIDRef"))
    var = odmod.ODVariable(name, index, subindex)
    default = obj.get("defaultValue")
    if default is None:
        default = _param_value(param, "defaultValue")
    actual = obj.get("actualValue")
    if actual is None:
        actual = _param_value(param, "actualValue")

    if obj.get("dataType"):
        var.data_type = int(obj.get("dataType"), 16)
        if not 0 < var.data_type <= 0x1B:  # as import_od: an unknown type is read as DOMAIN
            var.data_type = DOMAIN
    else:
        kids = list(param) if param is not None else []
        iec = next((_local(c) for c in kids if _local(c) in IEC_TYPES), None)
        bits = _child(param, "BITSTRING")
        if iec is not None:
            var.data_type = IEC_TYPES[iec]
        elif bits is not None:
            var.data_type = OCTET_STRING if default else DOMAIN
        else:
            raise ValueError(f"object {index:04X}:{subindex:02X} ({name}) has no data type")

    access = obj.get("accessType")
    if access in EDS_ACCESS:
        var.access_type = access
    else:
        raw = param.get("access", "read") if param is not None else "read"
        var.access_type = ACCESS.get(raw, "ro")
    var.pdo_mappable = (obj.get("PDOmapping") or "no") != "no"

    low, high = obj.get("lowLimit"), obj.get("highLimit")
    limits = _child(_child(param, "allowedValues"), "range")
    if low is None:
        low = _param_value(limits, "minValue")
    if high is None:
        high = _param_value(limits, "maxValue")
    if low is not None and _int(low) is not None:
        var.min = _int(low)
    if high is not None and _int(high) is not None:
        var.max = _int(high)

    if default is not None:
        var.default_raw = default
        if "$NODEID" in default.upper():
            var.relative = True
        try:
            var.default = _convert(node_id, var.data_type, default)
        except ValueError:
            pass
    if actual is not None:
        var.value_raw = actual
        try:
            var.value = _convert(node_id, var.data_type, actual)
        except ValueError:
            pass
    if param is not None:
        described = _child(param, "description")
        if described is not None and described.text:
            # one line: a DCF written from this dictionary keeps it as one INI value
            var.description = " ".join(described.text.split())
    return var


def signed_hex(data_type: int, raw: str, number: int) -> int:
    """A signed object's value written in hex is its bit pattern, as a log's bytes are:
    maxon's EPOS3 XDC gives one INTEGER32 defaultValue="-2147483648" and
    actualValue="0x80000000", and a DCF's ParameterValue=0xFFFF of an INTEGER16 is -1.
    canopen's import_od reads such values as the unsigned number; this reads them signed."""
    from canopen.objectdictionary import ODVariable
    from canopen.objectdictionary.datatypes import SIGNED_TYPES

    if data_type not in SIGNED_TYPES or not raw.strip().upper().startswith("0X"):
        return number
    bits = 8 * ODVariable.STRUCT_TYPES[data_type].size
    return number - (1 << bits) if (1 << (bits - 1)) <= number < (1 << bits) else number


def _convert(node_id: int | None, data_type: int, value: str):
    """A value string as canopen's EDS reader converts a DefaultValue/ParameterValue, and
    a signed type's hex value as the bit pattern it is (`signed_hex`)."""
    if data_type in (OCTET_STRING, DOMAIN):
        return bytes.fromhex(value)
    if data_type in (0x09, 0x0B):
        return value
    if data_type in (0x08, 0x11):
        return float(value)
    text = value.replace(" ", "").upper()
    if "$NODEID" in text:
        if node_id is None:
            raise ValueError("$NODEID without a node ID")
        rest = re.sub(r"\+?\$NODEID\+?", "", text)
        return (int(rest, 0) if rest else 0) + node_id
    return signed_hex(data_type, text, int(text, 0))
