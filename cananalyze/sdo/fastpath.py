"""Columnar shortcut for the commonest SDO traffic: an expedited request and its answer.

Polling objects by expedited upload/download is most of the SDO traffic on a
real bus, and running each frame through the stateful tracker costs ~10 us.
Here the pairs are found per batch with numpy: a clean request (exact command
byte, 8 data bytes) whose next frame on the same default channel is the
matching expedited response, or a server abort, within the timeout. Their
records and frame notes are built exactly as `SdoTracker` would build them;
everything else (segmented, block, odd bytes, learnt channels, pairs cut by a
batch boundary) still goes through the tracker. Whether a pair's channel is
idle is only known while walking the batch, so `plan()` proposes and the
processor decides (see `SdoProcessor`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..decoded import DecodedBatch
from ..frames import FLAG_TX
from ..protocol.datatypes import decode_value, value_decoder
from ..protocol.tables import abort_text
from .tracker import ObjectInfo

_UPLOAD_REQ = 0x40
_DOWNLOAD_REQ = (0x22, 0x23, 0x27, 0x2B, 0x2F)  # expedited, with or without size
_UPLOAD_RESP = (0x42, 0x43, 0x47, 0x4B, 0x4F)
_DOWNLOAD_RESP = 0x60
_ABORT = 0x80

# Expedited data length by command byte: size indicated -> 4 - n, else 4.
_EXP_LEN = np.zeros(256, np.int8)
for _b in (0x22, 0x42):
    _EXP_LEN[_b] = 4
for _b in (0x23, 0x43, 0x27, 0x47, 0x2B, 0x4B, 0x2F, 0x4F):
    _EXP_LEN[_b] = 4 - ((_b >> 2) & 3)


@dataclass
class FastPlan:
    """Candidate pairs of one batch, indexed by position in the SDO rows list.

    `partner[p]` is the response position of candidate request p (else -1);
    `is_partner[q]` marks candidate responses; `static_slow` what is never fast.
    """

    rows: np.ndarray  # batch row of each SDO position
    cand: np.ndarray  # bool: clean request whose next frame on its channel answers it
    partner: np.ndarray  # int: that answer's position, -1 when not a candidate
    is_partner: np.ndarray  # bool
    static_slow: np.ndarray  # bool: neither candidate nor candidate's answer
    req_cob: np.ndarray  # int: request COB-ID of each position's channel
    aborted: np.ndarray  # bool: the candidate answer is a server abort


def plan(batch: DecodedBatch, rows: np.ndarray, timeout: float, explicit: list[int]) -> FastPlan:
    fb = batch.frames
    m = len(rows)
    cid = fb.can_id[rows].astype(np.int64)
    is_req = (cid >= 0x601) & (cid <= 0x67F)
    is_resp = (cid >= 0x581) & (cid <= 0x5FF)
    node = np.where(is_req, cid - 0x600, cid - 0x580)
    usable = (is_req | is_resp) & (fb.dlc[rows] == 8) & ((fb.flags[rows] & ~np.uint8(FLAG_TX)) == 0)
    if fb.long_data:
        usable &= ~np.isin(rows, np.fromiter(fb.long_data, np.int64))
    if explicit:
        ex = np.asarray(explicit, np.int64)
        usable &= ~np.isin(0x600 + node, ex) & ~np.isin(0x580 + node, ex)
    d = fb.data[rows]
    b0 = d[:, 0]
    mux = (
        d[:, 1].astype(np.int64)
        | (d[:, 2].astype(np.int64) << 8)
        | (d[:, 3].astype(np.int64) << 16)
    )
    # the next SDO frame on the same channel (stable sort keeps time order inside a node)
    order = np.argsort(np.where(usable, node, 0), kind="stable")
    nxt = np.full(m, -1, np.int64)
    if m > 1:
        same = node[order[1:]] == node[order[:-1]]
        nxt[order[:-1][same]] = order[1:][same]
    upload = b0 == _UPLOAD_REQ
    download = np.isin(b0, _DOWNLOAD_REQ)
    cand = usable & is_req & (upload | download) & (nxt >= 0)
    q = np.where(cand, nxt, 0)
    bq = b0[q]
    answers = (
        (upload & np.isin(bq, _UPLOAD_RESP)) | (download & (bq == _DOWNLOAD_RESP)) | (bq == _ABORT)
    )
    t = fb.t[rows]
    latest = np.maximum.accumulate(t) if m else t  # any time the tracker may have advanced to
    cand &= usable[q] & is_resp[q] & answers & (mux[q] == mux) & ~(latest[q] - t > timeout)
    partner = np.where(cand, q, -1)
    is_partner = np.zeros(m, bool)
    is_partner[partner[cand]] = True
    return FastPlan(
        rows, cand, partner, is_partner, ~(cand | is_partner), 0x600 + node, b0 == _ABORT
    )


def build_pairs(
    fb,
    a: np.ndarray,
    b: np.ndarray,
    object_info: ObjectInfo | None,
    notes: bool = True,
    records: bool = True,
) -> tuple[list[dict], list[dict], list[dict]]:
    """Request notes, answer notes and records of taken pairs (request rows a, answer rows b).

    Ordinary answers are built column-wise here; aborts go through `pair_outputs`.
    `notes` / `records` False leave that part out (the lists stay empty).
    """
    want_notes, want_records = notes, records
    da, db = fb.data[a], fb.data[b]
    upload = da[:, 0] == _UPLOAD_REQ
    aborted = db[:, 0] == _ABORT
    length = np.where(upload, _EXP_LEN[db[:, 0]], _EXP_LEN[da[:, 0]]).astype(np.int64)
    raws = np.where(upload[:, None], db[:, 4:8], da[:, 4:8]).tobytes()
    hexes = raws.hex()
    index = (da[:, 1].astype(np.int64) | (da[:, 2].astype(np.int64) << 8)).tolist()
    sub = da[:, 3].tolist()
    node = (fb.can_id[a].astype(np.int64) - 0x600).tolist()
    t0 = fb.t[a].tolist()
    t1 = fb.t[b].tolist()
    sized = (da[:, 0] & 1).tolist()
    req_notes: list[dict] = []
    resp_notes: list[dict] = []
    out: list[dict] = []
    info_cache: dict = {}  # a poll loop asks for the same few objects over and over
    value_cache: dict = {}  # ... and often reads the same values
    decoders: dict = {}  # datatype -> value_decoder
    latency_cache: dict = {}  # t - t_start -> latency_ms
    for k, (up, ab, n, x, y, i, s, nd) in enumerate(
        zip(
            upload.tolist(),
            aborted.tolist(),
            length.tolist(),
            t0,
            t1,
            index,
            sub,
            node,
            strict=True,
        )
    ):
        if ab:
            rq, rs, rec, _ = pair_outputs(fb, int(a[k]), int(b[k]), nd, object_info)
            if want_notes:
                req_notes.append(rq)
                resp_notes.append(rs)
            if want_records:
                out.append(rec)
            continue
        data = hexes[8 * k : 8 * k + 2 * n]
        if not want_notes:
            pass
        elif up:
            where = f" 0x{i:04X}:{s}"
            req_notes.append(
                {
                    "role": f"upload request{where}",
                    "command": "initiate_upload_request",
                    "index": i,
                    "subindex": s,
                }
            )
            resp_notes.append(
                {
                    "role": f"expedited upload response{where} = {data}",
                    "command": "initiate_upload_response",
                    "index": i,
                    "subindex": s,
                }
            )
        else:
            where = f" 0x{i:04X}:{s}"
            size = f", {n} bytes" if sized[k] else ""
            req_notes.append(
                {
                    "role": f"expedited download request{where}{size}",
                    "command": "initiate_download_request",
                    "index": i,
                    "subindex": s,
                }
            )
            resp_notes.append(
                {
                    "role": f"download response{where}",
                    "command": "initiate_download_response",
                    "index": i,
                    "subindex": s,
                }
            )
        if not want_records:
            continue
        name = value = None
        if object_info is not None:
            key = (nd, i, s)
            known = info_cache.get(key, info_cache)
            if known is info_cache:
                known = info_cache[key] = object_info(nd, i, s)
            if known is not None:
                name, datatype = known
                vkey = (data, datatype)
                value = value_cache.get(vkey, value_cache)
                if value is value_cache:
                    dec = decoders.get(datatype)
                    if dec is None:
                        dec = decoders[datatype] = value_decoder(datatype)
                    value = value_cache[vkey] = dec(raws[4 * k : 4 * k + n])
        latency = latency_cache.get(y - x)  # a poll loop's latencies take few distinct values
        if latency is None:
            latency = latency_cache[y - x] = round(round((y - x) * 1000.0, 6), 3)
        out.append(
            {
                "kind": "sdo",
                "t_start": x,
                "t": y,
                "latency_ms": latency,
                "node": nd,
                "direction": "upload" if up else "download",
                "protocol": "expedited",
                "index": i,
                "subindex": s,
                "size": n,
                "data": data,
                "value": value,
                "name": name,
                "result": "ok",
                "abort_code": None,
                "abort_text": None,
                "detail": None,
                "frames": 2,
                "channel": [0x600 + nd, 0x580 + nd],
            }
        )
    return req_notes, resp_notes, out


def _mux(index: int, subindex: int) -> str:
    return f" 0x{index:04X}:{subindex}"


def pair_outputs(
    fb, row_req: int, row_resp: int, node: int, object_info: ObjectInfo | None
) -> tuple[dict, dict, dict, str]:
    """(request note, response note, record, result) of one fast pair, as the tracker makes them."""
    req = fb.data[row_req].tobytes()
    resp = fb.data[row_resp].tobytes()
    index = req[1] | (req[2] << 8)
    sub = req[3]
    where = _mux(index, sub)
    t0 = float(fb.t[row_req])
    t1 = float(fb.t[row_resp])
    upload = req[0] == _UPLOAD_REQ
    if upload:
        req_note = {"role": f"upload request{where}", "command": "initiate_upload_request"}
        data = b""
    else:
        size = f", {_EXP_LEN[req[0]]} bytes" if req[0] & 1 else ""
        req_note = {
            "role": f"expedited download request{where}{size}",
            "command": "initiate_download_request",
        }
        data = req[4 : 4 + _EXP_LEN[req[0]]]
    req_note["index"] = index
    req_note["subindex"] = sub
    code = None
    if resp[0] == _ABORT:
        code = int.from_bytes(resp[4:8], "little")
        text = abort_text(code)
        resp_note = {"role": f"abort by server{where}: 0x{code:08X} {text}", "command": "abort"}
        result = "abort"
    elif upload:
        data = resp[4 : 4 + _EXP_LEN[resp[0]]]
        resp_note = {
            "role": f"expedited upload response{where} = {data.hex()}",
            "command": "initiate_upload_response",
        }
        result = "ok"
    else:
        resp_note = {"role": f"download response{where}", "command": "initiate_download_response"}
        result = "ok"
    resp_note["index"] = index
    resp_note["subindex"] = sub
    name = value = None
    if object_info is not None:
        known = object_info(node, index, sub)
        if known is not None:
            name, datatype = known
            if result == "ok":
                value = decode_value(data, datatype)
    record = {
        "kind": "sdo",
        "t_start": t0,
        "t": t1,
        "latency_ms": round(round((t1 - t0) * 1000.0, 6), 3),
        "node": node,
        "direction": "upload" if upload else "download",
        "protocol": None
        if upload and code is not None
        else "expedited",  # an upload's answer tells
        "index": index,
        "subindex": sub,
        "size": len(data) if data or result == "ok" else None,
        "data": data.hex() if data or result == "ok" else None,
        "value": value,
        "name": name,
        "result": result,
        "abort_code": code,
        "abort_text": None if code is None else text,
        "detail": "aborted by server" if code is not None else None,
        "frames": 2,
        "channel": [0x600 + node, 0x580 + node],
    }
    return req_note, resp_note, record, result
