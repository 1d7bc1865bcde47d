"""Per-frame service fields and the one-line annotation: which service module says what.

This is the stateless view of one frame (what its bytes say on their own), for
the JSONL and text outputs. Each CiA 301 service's module (`nmt`, `sync`,
`time`, `emcy`, `pdo`, `sdo`, `lss`) holds its fields and its text; this only
dispatches. The stateful decoders (SDO transfers, PDO mapping) add to the
fields through DecodedBatch.notes. Only the output stage calls this, row by
row, for the rows it prints.
"""

from __future__ import annotations

from cananalyze.protocol import emcy, error_frame, lss, nmt, pdo, sdo, srdo, sync, usdo
from cananalyze.protocol import time as time_of_day
from cananalyze.protocol.services import Service


def frame_fields(service: int, data: bytes, rtr: bool = False, can_id: int = 0) -> dict:
    """Service-specific JSONL fields of one frame (names are a stable API, docs/outputs.md).

    `can_id`: an error frame's classes are in its identifier."""
    s = Service(service)
    if s is Service.ERROR_FRAME:
        return error_frame.fields(can_id, data)
    if s is Service.NMT:
        return nmt.command_fields(data)
    if s is Service.SYNC:
        return sync.fields(data)
    if s is Service.TIME:
        return time_of_day.fields(data)
    if s is Service.EMCY:
        return emcy.fields(data)
    if s in (Service.HEARTBEAT, Service.BOOTUP, Service.GUARD_RESPONSE):
        return nmt.state_fields(data, guard=s is Service.GUARD_RESPONSE)
    if s is Service.ERRCTL_INVALID:
        return nmt.errctl_invalid_fields(data)
    if s in (Service.SDO_REQUEST, Service.SDO_RESPONSE):
        return sdo.fields(data, s is Service.SDO_REQUEST)
    if s in (Service.USDO_REQUEST, Service.USDO_RESPONSE):
        return usdo.fields(data)
    if s in (Service.LSS_MASTER, Service.LSS_SLAVE):
        return lss.fields(data)
    return {}


def annotation(service: int, node: int, pdo_number: int, fields: dict, rtr: bool = False) -> str:
    """The human text after a frame in `decode` output."""
    s = Service(service)
    if s is Service.NMT:
        return nmt.command_text(fields)
    if s is Service.SYNC:
        return sync.text(fields)
    if s is Service.TIME:
        return time_of_day.text(fields)
    if s is Service.EMCY:
        return emcy.annotation(fields)
    if s in (Service.TPDO, Service.RPDO):
        return pdo.annotation(s is Service.TPDO, pdo_number, rtr, fields)
    if s in (Service.SDO_REQUEST, Service.SDO_RESPONSE):
        return sdo.annotation(fields)
    if s in (Service.USDO_REQUEST, Service.USDO_RESPONSE):
        return usdo.annotation(fields)
    if s is Service.HEARTBEAT:
        return nmt.heartbeat_text(fields)
    if s is Service.BOOTUP:
        return nmt.BOOTUP_TEXT
    if s is Service.GUARD_REQUEST:
        return nmt.GUARD_REQUEST_TEXT
    if s is Service.GUARD_RESPONSE:
        return nmt.guard_response_text(fields)
    if s is Service.ERRCTL_INVALID:
        return nmt.errctl_invalid_text(fields)
    if s in (Service.LSS_MASTER, Service.LSS_SLAVE):
        return lss.text(fields, master=s is Service.LSS_MASTER)
    if s is Service.ERROR_FRAME:
        return error_frame.text(fields)
    if s in (Service.SRDO, Service.SRDO_INVERTED):
        return srdo.annotation(pdo_number, s is Service.SRDO_INVERTED, fields)
    if s is Service.GFC:
        return srdo.GFC_TEXT
    if fields.get("message"):  # a DBC message on an identifier CANopen does not use
        return f"{fields['message']}  {pdo.signals_text(fields)}"
    return fields.get("label", "not CANopen (predefined connection set)")
