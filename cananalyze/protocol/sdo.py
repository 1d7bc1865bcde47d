"""SDO (CiA 301 7.2.4): command specifiers and bits, abort codes, and what one frame says.

One home for the command byte's layout (which the fast path, the tracker and
the simulator's client and server compose and match), the abort code texts,
how an object's index and sub-index are written, and the stateless reading of
one frame: the command specifier and its bits, index and subindex, expedited
data, abort code. This is what a frame means *outside* a block transfer;
inside one, a frame carries no command specifier at all (byte 0 is c +
seqno), and only the stateful tracker (`cananalyze.decode.sdo`) knows that. So this
module never guesses "block segment": the tracker overrides its answer.
"""

from __future__ import annotations

import struct

import numpy as np

from cananalyze.core.columns import bytecols

# Client command specifiers (ccs, bits 7..5 of byte 0, client -> server).
CCS_DOWNLOAD_SEGMENT = 0
CCS_INITIATE_DOWNLOAD = 1
CCS_INITIATE_UPLOAD = 2
CCS_UPLOAD_SEGMENT = 3
CS_ABORT = 4
CCS_BLOCK_UPLOAD = 5
CCS_BLOCK_DOWNLOAD = 6

# Server command specifiers (scs, server -> client).
SCS_UPLOAD_SEGMENT = 0
SCS_DOWNLOAD_SEGMENT = 1
SCS_INITIATE_UPLOAD = 2
SCS_INITIATE_DOWNLOAD = 3
SCS_BLOCK_DOWNLOAD = 5
SCS_BLOCK_UPLOAD = 6

# The other bits of byte 0, by command
SIZE_INDICATED = 0x01  # s: initiate frames (and block initiate: BLOCK_SIZE_INDICATED)
EXPEDITED = 0x02  # e: initiate frames
LAST_SEGMENT = 0x01  # c: segment frames, no more segments to come
TOGGLE = 0x10  # t: segment frames
CRC_SUPPORTED = 0x04  # cc / sc: block initiate frames
BLOCK_SIZE_INDICATED = 0x02  # s: block initiate frames
# Block sub-commands (bits 1..0; bit 0 alone for the downloading side's frames)
BLOCK_INITIATE, BLOCK_END, BLOCK_ACK, BLOCK_START = 0, 1, 2, 3
# Byte 0 of a block segment: its sequence number, and bit 7 on the transfer's last one
SEQNO_MASK = 0x7F
NO_MORE_SEGMENTS = 0x80
MAX_BLKSIZE = 127
EXPEDITED_SIZE = 4  # data bytes an expedited frame holds
SEGMENT_SIZE = 7  # data bytes a segment (or a block segment) holds


def command_byte(cs: int) -> int:
    """Byte 0 with the command specifier `cs` and every other bit 0."""
    return cs << 5


def initiate_byte(cs: int, size: int | None = None, expedited: bool = False) -> int:
    """Byte 0 of an initiate download request or initiate upload response: e, s, and n
    (the unused bytes) when an expedited frame says its size."""
    byte = command_byte(cs) | (EXPEDITED if expedited else 0)
    if size is not None:
        byte |= SIZE_INDICATED | ((EXPEDITED_SIZE - size) << 2 if expedited else 0)
    return byte


def expedited_size(byte: int) -> int:
    """Valid data bytes of an expedited initiate frame with command byte `byte`."""
    return EXPEDITED_SIZE - ((byte >> 2) & 0x03) if byte & SIZE_INDICATED else EXPEDITED_SIZE


def segment_byte(cs: int, toggle: int, unused: int = 0, last: bool = False) -> int:
    """Byte 0 of a segment frame (n = `unused` bytes of its 7) or of its answer."""
    return command_byte(cs) | toggle << 4 | unused << 1 | (LAST_SEGMENT if last else 0)


def block_byte(cs: int, sub: int, crc: bool = False, sized: bool = False, unused: int = 0) -> int:
    """Byte 0 of a block transfer frame: sub-command, CRC support and size bits, n."""
    flags = (CRC_SUPPORTED if crc else 0) | (BLOCK_SIZE_INDICATED if sized else 0)
    return command_byte(cs) | unused << 2 | flags | sub


# Reading a command byte: the inverse of the builders above, one place for every field
def command_specifier(byte: int) -> int:
    """The command specifier (ccs / scs / cs): the top three bits."""
    return byte >> 5


def segment_unused(byte: int) -> int:
    """n of a segment frame: bytes of its 7 that hold no data."""
    return (byte >> 1) & 0x07


def block_subcommand(byte: int, one_bit: bool = False) -> int:
    """A block frame's sub-command: two bits (ss / cs), or bit 0 alone (`one_bit`) in the
    initiate and end frames of a block's sender, whose bit 1 is the size flag (s)."""
    return byte & (0x01 if one_bit else 0x03)


def block_end_unused(byte: int) -> int:
    """n of a block end frame: bytes of the last segment that hold no data."""
    return (byte >> 2) & 0x07


# The command bytes the fast path matches whole
INITIATE_UPLOAD_REQUEST = command_byte(CCS_INITIATE_UPLOAD)
INITIATE_DOWNLOAD_RESPONSE = command_byte(SCS_INITIATE_DOWNLOAD)
ABORT = command_byte(CS_ABORT)

# CiA 301 table 22: SDO abort codes (the ones the simulator raises by name).
ABORT_TOGGLE = 0x05030000
ABORT_TIMEOUT = 0x05040000
ABORT_COMMAND = 0x05040001
ABORT_BLOCK_SIZE = 0x05040002
ABORT_SEQUENCE = 0x05040003
ABORT_CRC = 0x05040004
ABORT_WRITE_ONLY = 0x06010001
ABORT_READ_ONLY = 0x06010002
ABORT_NO_OBJECT = 0x06020000
ABORT_LENGTH = 0x06070010
ABORT_TOO_LONG = 0x06070012
ABORT_TOO_SHORT = 0x06070013
ABORT_NO_SUBINDEX = 0x06090011
ABORT_VALUE_RANGE = 0x06090030

ABORT_CODES: dict[int, str] = {
    ABORT_TOGGLE: "Toggle bit not alternated",
    ABORT_TIMEOUT: "SDO protocol timed out",
    ABORT_COMMAND: "Client/server command specifier not valid or unknown",
    ABORT_BLOCK_SIZE: "Invalid block size (block mode only)",
    ABORT_SEQUENCE: "Invalid sequence number (block mode only)",
    ABORT_CRC: "CRC error (block mode only)",
    0x05040005: "Out of memory",
    0x06010000: "Unsupported access to an object",
    ABORT_WRITE_ONLY: "Attempt to read a write only object",
    ABORT_READ_ONLY: "Attempt to write a read only object",
    ABORT_NO_OBJECT: "Object does not exist in the object dictionary",
    0x06040041: "Object cannot be mapped to the PDO",
    0x06040042: "The number and length of the objects to be mapped would exceed PDO length",
    0x06040043: "General parameter incompatibility reason",
    0x06040047: "General internal incompatibility in the device",
    0x06060000: "Access failed due to a hardware error",
    ABORT_LENGTH: "Data type does not match, length of service parameter does not match",
    ABORT_TOO_LONG: "Data type does not match, length of service parameter too high",
    ABORT_TOO_SHORT: "Data type does not match, length of service parameter too low",
    ABORT_NO_SUBINDEX: "Sub-index does not exist",
    ABORT_VALUE_RANGE: "Invalid value for parameter (download only)",
    0x06090031: "Value of parameter written too high (download only)",
    0x06090032: "Value of parameter written too low (download only)",
    0x06090036: "Maximum value is less than minimum value",
    0x060A0023: "Resource not available: SDO connection",
    0x08000000: "General error",
    0x08000020: "Data cannot be transferred or stored to the application",
    0x08000021: "Data cannot be transferred or stored to the application because of local control",
    0x08000022: "Data cannot be transferred or stored to the application because of the present device state",
    0x08000023: "Object dictionary dynamic generation fails or no object dictionary is present",
    0x08000024: "No data available",
}


def abort_text(code: int) -> str:
    return ABORT_CODES.get(code, f"Unknown abort code 0x{code:08X}")


def object_text(index: int, subindex: int | None = None) -> str:
    """'0x1018:01': an object as every text writes it (sub-index: two hex digits)."""
    return f"0x{index:04X}" if subindex is None else f"0x{index:04X}:{subindex:02X}"


def object_columns(index: np.ndarray, subindex: np.ndarray) -> np.ndarray:
    """`object_text` of each (index, subindex) below (0x10000, 0x100) as an (n, 9) matrix."""
    i = np.asarray(index, np.int64)
    s = np.asarray(subindex, np.int64)
    hexes = [bytecols.HEX_UPPER[(v >> k) & 15] for v, k in ((i, 12), (i, 8), (i, 4), (i, 0))]
    colon = np.full(i.size, ord(":"), np.uint8)
    sub = [bytecols.HEX_UPPER[(s >> 4) & 15], bytecols.HEX_UPPER[s & 15]]
    zero_x = [np.full(i.size, ord("0"), np.uint8), np.full(i.size, ord("x"), np.uint8)]
    return np.stack([*zero_x, *hexes, colon, *sub], axis=1)


_REQUEST_NAMES = {
    CCS_DOWNLOAD_SEGMENT: "download_segment_request",
    CCS_INITIATE_DOWNLOAD: "initiate_download_request",
    CCS_INITIATE_UPLOAD: "initiate_upload_request",
    CCS_UPLOAD_SEGMENT: "upload_segment_request",
    CS_ABORT: "abort",
}
_RESPONSE_NAMES = {
    SCS_UPLOAD_SEGMENT: "upload_segment_response",
    SCS_DOWNLOAD_SEGMENT: "download_segment_response",
    SCS_INITIATE_UPLOAD: "initiate_upload_response",
    SCS_INITIATE_DOWNLOAD: "initiate_download_response",
    CS_ABORT: "abort",
}
_BLOCK_UPLOAD_REQUEST = {
    BLOCK_INITIATE: "block_upload_initiate",
    BLOCK_END: "block_upload_end_response",
    BLOCK_ACK: "block_upload_ack",
    BLOCK_START: "block_upload_start",
}
_BLOCK_DOWNLOAD_RESPONSE = {
    BLOCK_INITIATE: "block_download_initiate_response",
    BLOCK_END: "block_download_end_response",
    BLOCK_ACK: "block_download_ack",
    BLOCK_START: "invalid",
}


def _multiplexer(data: bytes, out: dict) -> None:
    if len(data) >= 4:
        out["index"], out["subindex"] = struct.unpack_from("<HB", data, 1)


def describe_sdo(data: bytes, is_request: bool) -> dict:
    """Fields of one SDO frame, as its command byte defines them.

    Always has `command` (short name) and `cs` (the 3-bit specifier); `index`,
    `subindex`, `abort_code`, `abort_text`, `expedited`, `size_indicated`, `n`,
    `c`, `toggle`, `size`, `data` (hex of valid expedited bytes), `blksize`,
    `ackseq`, `crc`, `crc_supported`, `pst` when the command carries them.
    """
    if not data:
        return {"command": "empty", "cs": None}
    b0 = data[0]
    cs = command_specifier(b0)
    out: dict = {"cs": cs}
    if cs == CS_ABORT:
        out["command"] = "abort"
        _multiplexer(data, out)
        if len(data) >= 8:
            code = struct.unpack_from("<I", data, 4)[0]
            out["abort_code"] = code
            out["abort_text"] = abort_text(code)
        return out
    if is_request:
        return _describe_request(b0, cs, data, out)
    return _describe_response(b0, cs, data, out)


def _initiate_fields(b0: int, data: bytes, out: dict) -> None:
    """Initiate download request / initiate upload response: e, s, n and the data."""
    expedited = bool(b0 & EXPEDITED)
    size_indicated = bool(b0 & SIZE_INDICATED)
    out["expedited"] = expedited
    out["size_indicated"] = size_indicated
    payload = bytes(data[4:8])
    if expedited:
        n = EXPEDITED_SIZE - expedited_size(b0)
        out["n"] = n
        valid = payload[: EXPEDITED_SIZE - n]
        out["data"] = valid.hex()
        if size_indicated:
            out["size"] = len(valid)
    elif size_indicated and len(payload) == 4:
        out["size"] = struct.unpack("<I", payload)[0]


def _segment_fields(b0: int, data: bytes, out: dict, with_data: bool) -> None:
    out["toggle"] = int(bool(b0 & TOGGLE))
    if with_data:
        out["n"] = segment_unused(b0)
        out["c"] = b0 & LAST_SEGMENT
        out["data"] = bytes(data[1 : 8 - out["n"]]).hex()


def _block_ack(data: bytes, out: dict) -> None:
    """Block ack from either side: the last sequence number received, the next blksize."""
    if len(data) >= 3:
        out["ackseq"] = data[1]
        out["blksize"] = data[2]


def _block_initiate_or_end(
    b0: int, data: bytes, out: dict, what: str, initiate: str | None = None
) -> dict:
    """The sender's block frames (download client, upload server): initiate or end."""
    if block_subcommand(b0, one_bit=True) == BLOCK_END:
        out["command"] = f"{what}_end"
        out["n"] = block_end_unused(b0)
        if len(data) >= 3:
            out["crc"] = struct.unpack_from("<H", data, 1)[0]
    else:
        out["command"] = initiate or f"{what}_initiate"
        _multiplexer(data, out)
        out["crc_supported"] = bool(b0 & CRC_SUPPORTED)
        out["size_indicated"] = bool(b0 & BLOCK_SIZE_INDICATED)
        if out["size_indicated"] and len(data) >= 8:
            out["size"] = struct.unpack_from("<I", data, 4)[0]
    return out


def _describe_request(b0: int, cs: int, data: bytes, out: dict) -> dict:
    if cs in _REQUEST_NAMES:
        out["command"] = _REQUEST_NAMES[cs]
        if cs == CCS_INITIATE_DOWNLOAD:
            _multiplexer(data, out)
            _initiate_fields(b0, data, out)
        elif cs == CCS_INITIATE_UPLOAD:
            _multiplexer(data, out)
        elif cs == CCS_DOWNLOAD_SEGMENT:
            _segment_fields(b0, data, out, with_data=True)
        else:
            _segment_fields(b0, data, out, with_data=False)
        return out
    if cs == CCS_BLOCK_UPLOAD:
        sub = block_subcommand(b0)
        out["command"] = _BLOCK_UPLOAD_REQUEST[sub]
        if sub == BLOCK_INITIATE:
            _multiplexer(data, out)
            out["crc_supported"] = bool(b0 & CRC_SUPPORTED)
            if len(data) >= 6:
                out["blksize"] = data[4]
                out["pst"] = data[5]
        elif sub == BLOCK_ACK:
            _block_ack(data, out)
        return out
    if cs == CCS_BLOCK_DOWNLOAD:
        return _block_initiate_or_end(b0, data, out, "block_download")
    out["command"] = "invalid"
    return out


def _describe_response(b0: int, cs: int, data: bytes, out: dict) -> dict:
    if cs in _RESPONSE_NAMES:
        out["command"] = _RESPONSE_NAMES[cs]
        if cs == SCS_INITIATE_UPLOAD:
            _multiplexer(data, out)
            _initiate_fields(b0, data, out)
        elif cs == SCS_INITIATE_DOWNLOAD:
            _multiplexer(data, out)
        elif cs == SCS_UPLOAD_SEGMENT:
            _segment_fields(b0, data, out, with_data=True)
        else:
            _segment_fields(b0, data, out, with_data=False)
        return out
    if cs == SCS_BLOCK_DOWNLOAD:
        sub = block_subcommand(b0)
        out["command"] = _BLOCK_DOWNLOAD_RESPONSE[sub]
        if sub == BLOCK_INITIATE:
            _multiplexer(data, out)
            out["crc_supported"] = bool(b0 & CRC_SUPPORTED)
            if len(data) >= 5:
                out["blksize"] = data[4]
        elif sub == BLOCK_ACK:
            _block_ack(data, out)
        return out
    if cs == SCS_BLOCK_UPLOAD:
        return _block_initiate_or_end(
            b0, data, out, "block_upload", initiate="block_upload_initiate_response"
        )
    out["command"] = "invalid"
    return out


def fields(data: bytes, is_request: bool) -> dict:
    """JSONL fields of one SDO frame without its transfer's context (`describe_sdo`)."""
    out = describe_sdo(data, is_request)
    if "data" in out:  # the segment's valid bytes; the frame record's `data` is the raw payload
        out["sdo_data"] = out.pop("data")
    return out


def annotation(fields: dict) -> str:
    """The text of an SDO frame: its role in the transfer when the tracker placed it."""
    if fields.get("role"):
        return f"SDO {fields['role']}"
    text = "SDO " + str(fields.get("command", "")).replace("_", " ")
    if "index" in fields:
        text += " " + object_text(fields["index"], fields["subindex"])
    if "abort_code" in fields:
        text += f" 0x{fields['abort_code']:08X} {fields['abort_text']}"
    return text
