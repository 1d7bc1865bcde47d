"""SocketCAN error frames (linux/can/error.h): the error classes, as `candump -e` names them.

The class bits are in the identifier (CAN_ERR_FLAG set), the details in the data bytes:
lost-arbitration bit (byte 0), controller status (1), protocol violation type (2) and
location (3), transceiver status (4), TX/RX error counters (6, 7). Names and layout as
can-utils' `snprintf_can_error_frame` prints them, so a line can be compared with
candump's (there joined by ", " on one line instead of candump's newline and tab).
"""

from __future__ import annotations

CLASSES = (  # CAN_ERR_TX_TIMEOUT 0x001 .. CAN_ERR_CNT 0x200
    "tx-timeout",
    "lost-arbitration",
    "controller-problem",
    "protocol-violation",
    "transceiver-status",
    "no-acknowledgement-on-tx",
    "bus-off",
    "bus-error",
    "restarted-after-bus-off",
    "error-counter-tx-rx",
)
CONTROLLER = (  # data[1]: CAN_ERR_CRTL_RX_OVERFLOW 0x01 .. CAN_ERR_CRTL_ACTIVE 0x40
    "rx-overflow",
    "tx-overflow",
    "rx-error-warning",
    "tx-error-warning",
    "rx-error-passive",
    "tx-error-passive",
    "back-to-error-active",
)
PROTOCOL_TYPES = (  # data[2]: CAN_ERR_PROT_BIT 0x01 .. CAN_ERR_PROT_TX 0x80
    "single-bit-error",
    "frame-format-error",
    "bit-stuffing-error",
    "tx-dominant-bit-error",
    "tx-recessive-bit-error",
    "bus-overload",
    "active-error",
    "error-on-tx",
)
PROTOCOL_LOCATIONS = (  # data[3]: CAN_ERR_PROT_LOC_*, 0x00 .. 0x1F
    "unspecified", "unspecified", "id.28-to-id.21", "start-of-frame", "bit-srtr", "bit-ide",
    "id.20-to-id.18", "id.17-to-id.13", "crc-sequence", "reserved-bit-0", "data-field",
    "data-length-code", "bit-rtr", "reserved-bit-1", "id.4-to-id.0", "id.12-to-id.5",
    "unspecified", "active-error-flag", "intermission", "tolerate-dominant-bits",
    "unspecified", "unspecified", "passive-error-flag", "error-delimiter", "crc-delimiter",
    "acknowledge-slot", "end-of-frame", "acknowledge-delimiter", "overload-flag",
    "unspecified", "unspecified", "unspecified",
)  # fmt: skip
CAN_ERR_LOSTARB, CAN_ERR_CRTL, CAN_ERR_PROT, CAN_ERR_CNT = 0x002, 0x004, 0x008, 0x200


def _bits(value: int, names: tuple[str, ...]) -> list[str]:
    return [name for k, name in enumerate(names) if value & (1 << k)]


CAN_ERR_DLC = 8  # every SocketCAN error frame has 8 data bytes


def fields(can_id: int, data: bytes) -> dict:
    """JSONL fields of an error frame: its classes and the details each class carries.

    Only a SocketCAN error frame (8 bytes, as candump and pcap hold them) has classes in
    its identifier; others (ASC, and BLF's, whose identifier is the frame that failed)
    have none to show."""
    if len(data) != CAN_ERR_DLC:
        return {}
    cls = can_id & 0x1FFFFFFF
    d = bytes(data) + bytes(max(0, 8 - len(data)))
    out: dict = {"error_classes": _bits(cls, CLASSES)}
    if cls >> len(CLASSES):
        out["error_class_invalid"] = cls
    if cls & CAN_ERR_LOSTARB:
        out["lost_arbitration_bit"] = d[0]
    if cls & CAN_ERR_CRTL:
        out["controller"] = _bits(d[1], CONTROLLER)
    if cls & CAN_ERR_PROT:
        out["protocol"] = {
            "types": _bits(d[2], PROTOCOL_TYPES),
            "location": PROTOCOL_LOCATIONS[d[3] & 0x1F],
        }
    if cls & CAN_ERR_CNT or d[6] or d[7]:
        out["tx_errors"], out["rx_errors"] = d[6], d[7]
    return out


def text(f: dict) -> str:
    """'CAN error frame: controller-problem{rx-error-warning}, bus-error', as candump -e."""
    parts = []
    for name in f.get("error_classes", ()):
        if name == "lost-arbitration":
            name += f"{{at bit {f.get('lost_arbitration_bit', 0)}}}"
        elif name == "controller-problem":
            name += "{" + ",".join(f.get("controller", ())) + "}"
        elif name == "protocol-violation":
            p = f.get("protocol", {})
            name += "{{" + ",".join(p.get("types", ())) + "}{" + p.get("location", "") + "}}"
        elif name == "error-counter-tx-rx":
            continue  # printed once, below, as candump does
        parts.append(name)
    if "tx_errors" in f:
        parts.append(f"error-counter-tx-rx{{{{{f['tx_errors']}}}{{{f['rx_errors']}}}}}")
    if "error_class_invalid" in f:
        return f"CAN error frame: error class {f['error_class_invalid']:#x} is invalid"
    return "CAN error frame" + (": " + ", ".join(parts) if parts else "")
