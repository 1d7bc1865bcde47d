"""EMCY (CiA 301 7.2.7): error-code classes, error-register bits, the frame's fields and text.

The one place an emergency is put in words. `text` (one frame) and
`text_columns` (many frames as byte columns, for the text output and the event
log) build the same line from the same pieces (`error_text`, `register_text`);
the checks' findings and the dashboard use those pieces too.
"""

from __future__ import annotations

import functools

import numpy as np

from cananalyze.core.columns import bytecols

# CiA 301 table 21: emergency error code classes, matched on the high byte
# (or high nibble where only the nibble is defined). Longest match wins.
ERROR_CLASSES: dict[int, str] = {
    0x0000: "Error reset or no error",
    0x1000: "Generic error",
    0x2000: "Current",
    0x2100: "Current, CANopen device input side",
    0x2200: "Current inside the CANopen device",
    0x2300: "Current, CANopen device output side",
    0x3000: "Voltage",
    0x3100: "Mains voltage",
    0x3200: "Voltage inside the CANopen device",
    0x3300: "Output voltage",
    0x4000: "Temperature",
    0x4100: "Ambient temperature",
    0x4200: "Device temperature",
    0x5000: "CANopen device hardware",
    0x6000: "CANopen device software",
    0x6100: "Internal software",
    0x6200: "User software",
    0x6300: "Data set",
    0x7000: "Additional modules",
    0x8000: "Monitoring",
    0x8100: "Communication",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "Life guard error or heartbeat error",
    0x8140: "Recovered from bus off",
    0x8150: "CAN-ID collision",
    0x8200: "Protocol error",
    0x8210: "PDO not processed due to length error",
    0x8220: "PDO length exceeded",
    0x8230: "DAM MPDO not processed, destination object not available",
    0x8240: "Unexpected SYNC data length",
    0x8250: "RPDO timeout",
    0x9000: "External error",
    0xF000: "Additional functions",
    0xFF00: "Device specific",
}
_MASKS = (0xFFF0, 0xFF00, 0xF000)  # after the exact code, most specific first
UNKNOWN_CLASS = "Unknown"

# CiA 301 object 0x1001 error register bits.
ERROR_REGISTER_BITS: dict[int, str] = {
    0: "generic",
    1: "current",
    2: "voltage",
    3: "temperature",
    4: "communication",
    5: "device profile specific",
    6: "reserved",
    7: "manufacturer specific",
}

SIZE = 8  # CiA 301: error code, error register, 5 manufacturer bytes
MIN_BYTES = 3  # what can be read of a shorter one: the error code and register
MALFORMED = "malformed: fewer than 3 bytes"
RESET_TEXT = "EMCY error reset / no error"
_ERROR = "0x{:04X} {}"  # an error code and its class
_REGISTER = "register 0x{:02X} [{}]"


def error_class(code: int) -> str:
    """Most specific CiA 301 name for an emergency error code."""
    if code in ERROR_CLASSES:
        return ERROR_CLASSES[code]
    for mask in _MASKS:
        name = ERROR_CLASSES.get(code & mask)
        if name is not None:
            return name
    return UNKNOWN_CLASS


# error code class (high nibble) -> the error register bit it sets besides bit 0 (generic)
_CLASS_REGISTER_BIT = {0x2: 0x02, 0x3: 0x04, 0x4: 0x08, 0x8: 0x10, 0xF: 0x80}


def register_for(code: int) -> int:
    """The 0x1001 value that goes with an error code (0 for an error reset)."""
    if code == 0:
        return 0
    return 0x01 | _CLASS_REGISTER_BIT.get(code >> 12, 0)


def register_names(register: int) -> list[str]:
    return [name for bit, name in ERROR_REGISTER_BITS.items() if register >> bit & 1]


def error_text(code: int) -> str:
    """'0x8130 Life guard error or heartbeat error': an error code in words."""
    return _ERROR.format(code, error_class(code))


def register_text(register: int) -> str:
    """'register 0x11 [generic,communication]'."""
    return _REGISTER.format(register, ",".join(register_names(register)) or "none")


def error_lines(codes: np.ndarray, registers: np.ndarray) -> np.ndarray:
    """'EMCY {error_text}; {register_text}' of each (code, register), as a str object array.

    A fault storm lists tens of thousands of errors, of as many distinct codes: built
    as byte columns (code in hex, its class and register from tables) joined in one
    pass, not formatted per row (1-2 us each).
    """
    codes = np.asarray(codes, np.int64)
    n = codes.size
    uregs, reg_at = np.unique(np.asarray(registers, np.int64), return_inverse=True)
    parts = [
        _head_block(codes),
        bytecols.padded_table([register_text(r).encode() for r in uregs.tolist()])[
            reg_at.reshape(-1)
        ],
    ]
    out = np.empty(n, object)
    out[:] = bytecols.joined_rows(parts, n) if n else []
    return out


def code_texts(codes: np.ndarray) -> list[str]:
    """'0x8130' of each error code (a finding's measured value), as byte columns."""
    codes = np.asarray(codes, np.int64)
    return bytecols.joined_rows([_hex_code(codes)], codes.size) if codes.size else []


_NIBBLES = np.array([12, 8, 4, 0], np.int64)


def _hex_code(codes: np.ndarray) -> np.ndarray:
    """`f"0x{code:04X}"` of each 16-bit code as an (n, 6) byte matrix."""
    out = np.empty((codes.size, 6), np.uint8)
    out[:, :2] = np.frombuffer(b"0x", np.uint8)
    out[:, 2:] = bytecols.HEX_UPPER[(codes[:, None] >> _NIBBLES) & 15]
    return out


def fields(data: bytes) -> dict:
    """JSONL fields of an EMCY frame; `problem` (and nulls) when it is too short."""
    if len(data) < MIN_BYTES:
        return {
            "error_code": None,
            "error_class": None,
            "error_register": None,
            "manufacturer": data.hex(),
            "reset": False,
            "problem": MALFORMED,
        }
    code = data[0] | data[1] << 8
    return {
        "error_code": code,
        "error_class": error_class(code),
        "error_register": data[2],
        "error_register_bits": register_names(data[2]),
        "manufacturer": data[3:8].hex(),
        "reset": code == 0,
    }


def text(code: int, register: int, manufacturer: str) -> str:
    """The line of one EMCY (code, register, manufacturer bytes as hex)."""
    if code == 0:
        return RESET_TEXT
    return f"EMCY {error_text(code)}; {register_text(register)}; mfr {manufacturer or '-'}"


def annotation(fields: dict) -> str:
    """`text` of a frame's fields, and the profile's reading of the vendor bytes if any."""
    if fields.get("error_code") is None:
        return f"EMCY ({fields.get('problem', MALFORMED)})"
    line = text(fields["error_code"], fields["error_register"], fields["manufacturer"])
    decoded = fields.get("manufacturer_decoded")
    if decoded and not fields["reset"]:
        line += f" ({decoded_words(decoded)})"
    return line


def decoded_words(decoded: dict) -> str:
    """A profile's reading of the vendor bytes in words (decode's line, check's finding)."""
    return decoded.get("meaning") or ", ".join(decoded.get("flags") or []) or str(decoded)


@functools.cache
def _class_blocks() -> tuple[np.ndarray, np.ndarray]:
    """(index of every 16-bit code's class, " {error_class}; " of each as a NUL-padded
    matrix), built once: a batch's heads are then two gathers, not a search per mask.

    Each mask, from the least to the most specific, overwrites the codes it names:
    a masked key covers the contiguous run of codes under it, so the most specific name
    wins, as `error_class`'s first hit does.
    """
    keys = sorted(ERROR_CLASSES)
    index = np.full(1 << 16, len(keys), np.uint16)  # UNKNOWN_CLASS after the keys
    for mask in (*reversed(_MASKS), 0xFFFF):
        for i, key in enumerate(keys):
            if key & mask == key:
                index[key : (key | (~mask & 0xFFFF)) + 1] = i
    names = [ERROR_CLASSES[k] for k in keys] + [UNKNOWN_CLASS]
    return index, bytecols.padded_table([f" {name}; ".encode() for name in names])


def _head_block(code: np.ndarray) -> np.ndarray:
    """The "EMCY {error_text}; " of each code as a NUL-padded block: the four hex digits and
    the class by numpy (a format per distinct code was half of `text_columns`)."""
    index, blocks = _class_blocks()
    lead = bytecols.repeat(b"EMCY ", len(code))
    return np.concatenate((lead, _hex_code(code), blocks[index[code]]), axis=1)


def text_columns(data: np.ndarray, dlc: np.ndarray) -> list[np.ndarray]:
    """`text` of m EMCY frames as column blocks (NUL-padded uint8 matrices to put side
    by side and compact); short frames get `annotation`'s malformed text.

    data: (m, 8) uint8, dlc: m byte counts. The class is looked up once per distinct
    code, the register names once per distinct value, the vendor bytes are hex by numpy.
    """
    dlc = np.asarray(dlc).astype(np.int64)
    code = data[:, 0].astype(np.int64) | data[:, 1].astype(np.int64) << 8
    regs, reg_at = np.unique(data[:, 2], return_inverse=True)
    registers = [f"{register_text(r)}; mfr ".encode() for r in regs.tolist()]
    head = _head_block(code)
    register = bytecols.padded_table(registers)[reg_at.reshape(-1)]
    shown = np.clip(np.minimum(dlc, 8) - MIN_BYTES, 0, 5)
    mfr = bytecols.hex_bytes(np.ascontiguousarray(data[:, MIN_BYTES:8]), shown)
    mfr[:, 0] = np.where(shown == 0, ord("-"), mfr[:, 0])
    # an error reset or a short frame: its own text, the other blocks blank
    other = np.where(dlc < MIN_BYTES, 2, np.where(code == 0, 1, 0))
    plain = ["", RESET_TEXT, annotation(fields(b""))]
    special = bytecols.padded_table([t.encode() for t in plain])[other]
    blank = other != 0
    for block in (head, register, mfr):
        block[blank] = bytecols.PAD
    return [head, register, mfr, special]
