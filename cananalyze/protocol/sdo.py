"""Stateless decoding of one SDO frame (CiA 301 section 7.2.4.3).

What one frame says on its own: the command specifier and its bits, index and
subindex, expedited data, abort code. This is what a frame means *outside* a
block transfer; inside one, a frame carries no command specifier at all (byte 0
is c + seqno), and only the stateful tracker (`cananalyze.sdo`) knows that. So
this module never guesses "block segment": the tracker overrides its answer.
"""

from __future__ import annotations

import struct

from .tables import abort_text

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
    0: "block_upload_initiate",
    1: "block_upload_end_response",
    2: "block_upload_ack",
    3: "block_upload_start",
}
_BLOCK_DOWNLOAD_RESPONSE = {
    0: "block_download_initiate_response",
    1: "block_download_end_response",
    2: "block_download_ack",
    3: "invalid",
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
    cs = b0 >> 5
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
    expedited = bool(b0 & 0x02)
    size_indicated = bool(b0 & 0x01)
    out["expedited"] = expedited
    out["size_indicated"] = size_indicated
    payload = bytes(data[4:8])
    if expedited:
        n = (b0 >> 2) & 0x03 if size_indicated else 0
        out["n"] = n
        valid = payload[: 4 - n] if size_indicated else payload
        out["data"] = valid.hex()
        if size_indicated:
            out["size"] = len(valid)
    elif size_indicated and len(payload) == 4:
        out["size"] = struct.unpack("<I", payload)[0]


def _segment_fields(b0: int, data: bytes, out: dict, with_data: bool) -> None:
    out["toggle"] = (b0 >> 4) & 1
    if with_data:
        out["n"] = (b0 >> 1) & 0x07
        out["c"] = b0 & 1
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
    if b0 & 0x01:
        out["command"] = f"{what}_end"
        out["n"] = (b0 >> 2) & 0x07
        if len(data) >= 3:
            out["crc"] = struct.unpack_from("<H", data, 1)[0]
    else:
        out["command"] = initiate or f"{what}_initiate"
        _multiplexer(data, out)
        out["crc_supported"] = bool(b0 & 0x04)
        out["size_indicated"] = bool(b0 & 0x02)
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
        sub = b0 & 0x03
        out["command"] = _BLOCK_UPLOAD_REQUEST[sub]
        if sub == 0:
            _multiplexer(data, out)
            out["crc_supported"] = bool(b0 & 0x04)
            if len(data) >= 6:
                out["blksize"] = data[4]
                out["pst"] = data[5]
        elif sub == 2:
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
        sub = b0 & 0x03
        out["command"] = _BLOCK_DOWNLOAD_RESPONSE[sub]
        if sub == 0:
            _multiplexer(data, out)
            out["crc_supported"] = bool(b0 & 0x04)
            if len(data) >= 5:
                out["blksize"] = data[4]
        elif sub == 2:
            _block_ack(data, out)
        return out
    if cs == SCS_BLOCK_UPLOAD:
        return _block_initiate_or_end(
            b0, data, out, "block_upload", initiate="block_upload_initiate_response"
        )
    out["command"] = "invalid"
    return out
