"""Per-frame service fields and the one-line annotation, for the JSONL and text outputs.

This is the stateless view of one frame (what its bytes say on their own). The
stateful decoders (SDO transfers, PDO mapping) add to it through DecodedBatch.notes.
Only the output stage calls this, row by row, for the rows it prints.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from .sdo import describe_sdo
from .services import Service
from .tables import LSS_COMMANDS, NMT_COMMANDS, NMT_STATES, emcy_class, error_register_names

CANOPEN_EPOCH = datetime(1984, 1, 1, tzinfo=UTC)


def sdo_fields(data: bytes, is_request: bool) -> dict:
    """What one SDO frame says without its transfer's context (see protocol.sdo)."""
    fields = describe_sdo(data, is_request)
    if "data" in fields:  # the segment's valid bytes; the frame record's `data` is the raw payload
        fields["sdo_data"] = fields.pop("data")
    return fields


def time_of_day(data: bytes) -> str | None:
    """CiA 301 TIME_OF_DAY: ms after midnight (28 bits) + days since 1984-01-01."""
    if len(data) < 6:
        return None
    ms = int.from_bytes(data[0:4], "little") & 0x0FFFFFFF
    days = int.from_bytes(data[4:6], "little")
    when = CANOPEN_EPOCH + timedelta(days=days, milliseconds=ms)
    return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def frame_fields(service: int, data: bytes, rtr: bool = False) -> dict:
    """Service-specific JSONL fields of one frame (names are a stable API, see README)."""
    s = Service(service)
    if s is Service.NMT:
        if len(data) < 2:
            return {"command": None, "target": None}
        return {"command": NMT_COMMANDS.get(data[0], f"unknown 0x{data[0]:02X}"), "target": data[1]}
    if s is Service.SYNC:
        return {"counter": data[0] if data else None}
    if s is Service.TIME:
        return {"time": time_of_day(data)}
    if s is Service.EMCY:
        if len(data) < 3:
            return {
                "error_code": None,
                "error_class": None,
                "error_register": None,
                "manufacturer": data.hex(),
                "reset": False,
            }
        code = data[0] | data[1] << 8
        return {
            "error_code": code,
            "error_class": emcy_class(code),
            "error_register": data[2],
            "error_register_bits": error_register_names(data[2]),
            "manufacturer": data[3:8].hex(),
            "reset": code == 0,
        }
    if s in (Service.HEARTBEAT, Service.BOOTUP, Service.GUARD_RESPONSE):
        if not data:
            return {"state": None}
        out: dict = {"state": NMT_STATES.get(data[0] & 0x7F, f"unknown 0x{data[0] & 0x7F:02X}")}
        if s is Service.GUARD_RESPONSE:
            out["toggle"] = data[0] >> 7
        return out
    if s in (Service.SDO_REQUEST, Service.SDO_RESPONSE):
        return sdo_fields(data, s is Service.SDO_REQUEST)
    if s in (Service.LSS_MASTER, Service.LSS_SLAVE):
        if not data:
            return {"command": None}
        return {"command": LSS_COMMANDS.get(data[0], f"unknown 0x{data[0]:02X}")}
    return {}


def annotation(service: int, node: int, pdo: int, fields: dict, rtr: bool = False) -> str:
    """The human text after a frame in `decode` output."""
    s = Service(service)
    if s is Service.NMT:
        target = fields.get("target")
        who = "all nodes" if target == 0 else f"node {target}"
        return (
            f"NMT {fields.get('command')} {who}"
            if target is not None
            else "NMT (malformed: needs 2 bytes)"
        )
    if s is Service.SYNC:
        c = fields.get("counter")
        return "SYNC" if c is None else f"SYNC counter {c}"
    if s is Service.TIME:
        return f"TIME {fields.get('time') or '(malformed)'}"
    if s is Service.EMCY:
        if fields.get("error_code") is None:
            return "EMCY (malformed: fewer than 3 bytes)"
        if fields["reset"]:
            return "EMCY error reset / no error"
        regs = ",".join(fields.get("error_register_bits") or []) or "none"
        text = (
            f"EMCY 0x{fields['error_code']:04X} {fields['error_class']}; "
            f"register 0x{fields['error_register']:02X} [{regs}]; mfr {fields['manufacturer'] or '-'}"
        )
        decoded = fields.get("manufacturer_decoded")
        if decoded:
            words = decoded.get("meaning") or ", ".join(decoded.get("flags") or []) or str(decoded)
            text += f" ({words})"
        return text
    if s in (Service.TPDO, Service.RPDO):
        kind = "TPDO" if s is Service.TPDO else "RPDO"
        text = f"{kind}{pdo}" + (" remote request" if rtr else "")
        sig = fields.get("signals")
        if sig:
            units = fields.get("units") or {}
            text += "  " + " ".join(_fmt_signal(k, v, units.get(k)) for k, v in sig.items())
        if fields.get("pdo_problem"):
            text += f"  [{fields['pdo_problem']}]"
        return text
    if s in (Service.SDO_REQUEST, Service.SDO_RESPONSE):
        if fields.get("role"):
            return f"SDO {fields['role']}"
        text = "SDO " + str(fields.get("command", "")).replace("_", " ")
        if "index" in fields:
            text += f" 0x{fields['index']:04X}:{fields['subindex']:02X}"
        if "abort_code" in fields:
            text += f" 0x{fields['abort_code']:08X} {fields['abort_text']}"
        return text
    if s is Service.HEARTBEAT:
        return f"heartbeat {fields.get('state') or '(empty)'}"
    if s is Service.BOOTUP:
        return "boot-up"
    if s is Service.GUARD_REQUEST:
        return "node guarding request (RTR)"
    if s is Service.GUARD_RESPONSE:
        return f"node guarding response {fields.get('state')} toggle {fields.get('toggle')}"
    if s is Service.LSS_MASTER:
        return f"LSS master {fields.get('command')}"
    if s is Service.LSS_SLAVE:
        return f"LSS slave {fields.get('command')}"
    if s is Service.ERROR_FRAME:
        return "CAN error frame"
    return fields.get("label", "not CANopen (predefined connection set)")


def _fmt_signal(name: str, value, unit: str | None) -> str:
    if isinstance(value, float):
        value = f"{value:.6g}"
    return f"{name}={value}" + (f" {unit}" if unit else "")
