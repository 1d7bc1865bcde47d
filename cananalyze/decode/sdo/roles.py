"""The frame roles of the fast path's expedited pairs ("upload request 0x1018:01", ...),
worded once, as byte columns.

The text and JSONL outputs take the columns as they are (a polled bus has a few hundred
thousand such pairs per 10M frames); the batch's notes dict gets the same words, split
into one note per frame, only when someone reads it. Aborted pairs (rare) are worded by
`fastpath.pair_outputs`. The tracker words every other transfer's frames, and
tests/decode/test_sdo_fastpath.py holds both to the tracker's words.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.decode.sdo.fastpath import pair_outputs
from cananalyze.protocol.sdo import SIZE_INDICATED, object_columns

_REQ_ROLE = bytecols.padded_table([b"SDO upload request ", b"SDO expedited download request "])
_RESP_ROLE = bytecols.padded_table([b"SDO expedited upload response ", b"SDO download response "])
_EQUALS = bytecols.padded_table([b"", b" = "])
_BYTES = bytecols.padded_table([b"", b", ", b" bytes"])
_COMMANDS = (
    ("initiate_download_request", "initiate_download_response"),
    ("initiate_upload_request", "initiate_upload_response"),
)


def pair_roles(
    fb, fields, req: np.ndarray, resp: np.ndarray, end: bytes
) -> tuple[np.ndarray, np.ndarray]:
    """("SDO <request role>" + end, "SDO <answer role>" + end) of the fast pairs at
    rows `req` and `resp` of `fb`, with their record columns `fields`
    (`RecordColumns`); as (m, w) uint8 rows, NUL-padded."""
    a = fields.arrays
    m = len(fields)
    upload = a["upload"]
    where = [object_columns(a["index"], a["subindex"])]  # "0x1018:01"
    endm = bytecols.repeat(end, m)
    # request: "upload request 0x..:ss" / "expedited download request 0x..:ss[, n bytes]"
    sized = ~upload & ((fb.data[req, 0] & SIZE_INDICATED) != 0)
    size_digit = np.where(sized, 48 + a["size"] % 10, bytecols.PAD).astype(np.uint8)[:, None]
    req_parts = [_REQ_ROLE[(~upload).astype(np.intp)], *where]
    req_parts += [_BYTES[sized.astype(np.intp)], size_digit, _BYTES[2 * sized], endm]
    # answer: "expedited upload response 0x..:ss = <hex>" / "download response 0x..:ss"
    shown = np.where(upload, a["data_len"], 0)
    resp_parts = [_RESP_ROLE[(~upload).astype(np.intp)], *where]
    resp_parts += [_EQUALS[upload.astype(np.intp)], bytecols.hex_bytes(a["raw"], shown), endm]
    req_role, resp_role = _matrix(req_parts, m), _matrix(resp_parts, m)
    for j in sorted(fields.held):  # aborted pairs: the roles pair_outputs gives them
        rq, rs, _, _ = pair_outputs(fb, int(req[j]), int(resp[j]), int(a["node"][j]), None)
        req_role = _put(req_role, j, ("SDO " + rq["role"]).encode() + end)
        resp_role = _put(resp_role, j, ("SDO " + rs["role"]).encode() + end)
    return req_role, resp_role


def pair_notes(fb, fields, req: np.ndarray, resp: np.ndarray) -> tuple[list[dict], list[dict]]:
    """The request's and the answer's frame notes of each fast pair, in the tracker's keys
    (role, command, index, subindex): the roles above, split per frame."""
    m = len(fields)
    req_role, resp_role = pair_roles(fb, fields, req, resp, b"")
    a = fields.arrays
    index, sub, upload = a["index"].tolist(), a["subindex"].tolist(), a["upload"].tolist()
    out: tuple[list[dict], list[dict]] = ([], [])
    for side, matrix in enumerate((req_role, resp_role)):
        notes = out[side]
        roles = bytecols.split_rows(*bytecols.compact([matrix], m, with_ends=True))
        for j, role in enumerate(roles):
            command = _COMMANDS[upload[j]][side]
            notes.append(
                {"role": role[4:], "command": command, "index": index[j], "subindex": sub[j]}
            )
    for j in fields.held:  # aborted: pair_outputs's notes (command "abort")
        rq, rs, _, _ = pair_outputs(fb, int(req[j]), int(resp[j]), int(a["node"][j]), None)
        out[0][j], out[1][j] = rq, rs
    return out


def _matrix(parts: list[np.ndarray], m: int) -> np.ndarray:
    """The parts side by side (their NULs are dropped when the output is compacted)."""
    return np.concatenate([np.broadcast_to(p, (m, p.shape[1])) for p in parts], axis=1)


def _put(matrix: np.ndarray, j: int, text: bytes) -> np.ndarray:
    """matrix with row j replaced by `text` (widened when it is longer)."""
    if len(text) > matrix.shape[1]:
        wider = np.zeros((matrix.shape[0], len(text)), np.uint8)
        wider[:, : matrix.shape[1]] = matrix
        matrix = wider
    matrix[j] = bytecols.PAD
    matrix[j, : len(text)] = np.frombuffer(text, np.uint8)
    return matrix
