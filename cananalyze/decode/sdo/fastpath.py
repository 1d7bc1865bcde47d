"""Columnar shortcut for the commonest SDO traffic: an expedited request and its answer.

Polling objects by expedited upload/download is most of the SDO traffic on a
real bus, and running each frame through the stateful tracker costs ~10 us.
Here the pairs are found per batch with numpy: a clean request (exact command
byte, 8 data bytes) whose next frame on the same default channel is the
matching expedited response, or a server abort, within the timeout. Their
records and frame notes are built exactly as `SdoTracker` would build them.
So are the notes of a stray initiate response (one whose channel has no transfer
in progress: a log that starts mid-poll, a lost request; half the frames that
fell back on the benchmark's bus), which changes no state. Everything else
(segmented, block, odd bytes, learnt channels, pairs cut by a batch boundary,
answers naming another object) still goes through the tracker. Whether a pair's channel is
idle is only known while walking the batch, so `plan()` proposes and the
processor decides (see `SdoProcessor`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cananalyze.core.frames import FLAG_TX
from cananalyze.core.records import DecodedBatch
from cananalyze.core.sdo_records import RecordColumns, SdoColumns
from cananalyze.decode.sdo.tracker import ObjectInfo
from cananalyze.decode.sdo.words import sdo_words
from cananalyze.devices.words import WORDED
from cananalyze.protocol import sdo
from cananalyze.protocol.datatypes import decode_column, decode_int_column, decode_value

_WORDED = np.array(sorted(WORDED), np.int64)

_UPLOAD_REQ = sdo.INITIATE_UPLOAD_REQUEST
_DOWNLOAD_RESP = sdo.INITIATE_DOWNLOAD_RESPONSE
_ABORT = sdo.ABORT
_SCS_UPLOAD, _SCS_DOWNLOAD = sdo.SCS_INITIATE_UPLOAD, sdo.SCS_INITIATE_DOWNLOAD
_SIZES = (None, 4, 3, 2, 1)  # expedited, without or with the size (then 4 - n bytes)
_DOWNLOAD_REQ = tuple(sdo.initiate_byte(sdo.CCS_INITIATE_DOWNLOAD, n, True) for n in _SIZES)
_UPLOAD_RESP = tuple(sdo.initiate_byte(sdo.SCS_INITIATE_UPLOAD, n, True) for n in _SIZES)

# Expedited data length by command byte (of the expedited initiate frames above)
_EXP_LEN = np.zeros(256, np.int8)
for _b in _DOWNLOAD_REQ + _UPLOAD_RESP:
    _EXP_LEN[_b] = sdo.expedited_size(_b)
# command byte -> is one of them (a lookup: np.isin sorts its arguments on every call)
_IS_DOWNLOAD_REQ = np.isin(np.arange(256), _DOWNLOAD_REQ)
_IS_UPLOAD_RESP = np.isin(np.arange(256), _UPLOAD_RESP)


@dataclass
class Gathered:
    """The SDO rows' columns as `plan` read them (payload bytes, times, COB-IDs), by
    position in the rows list: the pair functions read them there (as they would a
    FrameBatch's, positions for rows), not by gathering from the whole batch again."""

    data: np.ndarray  # (m, width) uint8, the batch's data rows
    t: np.ndarray  # float64
    can_id: np.ndarray  # int64


@dataclass
class FastPlan:
    """Candidate pairs of one batch, indexed by position in the SDO rows list.

    `partner[p]` is the response position of candidate request p (else -1);
    `is_partner[q]` marks candidate responses; `stray` initiate responses that are no
    candidate's answer (fast when their channel is idle); `static_slow` what is never fast.
    """

    rows: np.ndarray  # batch row of each SDO position
    cand: np.ndarray  # bool: clean request whose next frame on its channel answers it
    partner: np.ndarray  # int: that answer's position, -1 when not a candidate
    is_partner: np.ndarray  # bool
    static_slow: np.ndarray  # bool: neither candidate nor candidate's answer
    req_cob: np.ndarray  # int: request COB-ID of each position's channel
    aborted: np.ndarray  # bool: the candidate answer is a server abort
    stray: np.ndarray  # bool: an initiate response that answers no candidate
    seen: Gathered  # the rows' columns, by position


def plan(
    batch: DecodedBatch,
    rows: np.ndarray,
    timeout: float,
    explicit: list[int],
    d: np.ndarray | None = None,
) -> FastPlan:
    """`d`: the rows' data bytes when the caller read them already (`_rows(fb.data, rows)`)."""
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
    if d is None:
        d = _rows(fb.data, rows)
    b0 = d[:, 0]
    mux = (
        d[:, 1].astype(np.int64)
        | (d[:, 2].astype(np.int64) << 8)
        | (d[:, 3].astype(np.int64) << 16)
    )
    # the next SDO frame on the same channel (stable sort keeps time order inside a node);
    # frames the fast path cannot take (short, flagged) still count: the tracker sees them
    # (nodes fit a byte: numpy's stable sort of bytes is a radix sort, ~15x an int64 one)
    order = np.argsort(np.where(is_req | is_resp, node, 0).astype(np.uint8), kind="stable")
    nxt = np.full(m, -1, np.int64)
    if m > 1:
        same = node[order[1:]] == node[order[:-1]]
        nxt[order[:-1][same]] = order[1:][same]
    upload = b0 == _UPLOAD_REQ
    download = _IS_DOWNLOAD_REQ[b0]
    cand = usable & is_req & (upload | download) & (nxt >= 0)
    q = np.where(cand, nxt, 0)
    bq = b0[q]
    answers = (upload & _IS_UPLOAD_RESP[bq]) | (download & (bq == _DOWNLOAD_RESP)) | (bq == _ABORT)
    t = fb.t[rows]
    latest = np.maximum.accumulate(t) if m else t  # any time the tracker may have advanced to
    cand &= usable[q] & is_resp[q] & answers & (mux[q] == mux) & ~(latest[q] - t > timeout)
    partner = np.where(cand, q, -1)
    is_partner = np.zeros(m, bool)
    is_partner[partner[cand]] = True
    scs = sdo.command_specifier(b0)
    stray = usable & is_resp & ~is_partner & ((scs == _SCS_UPLOAD) | (scs == _SCS_DOWNLOAD))
    return FastPlan(
        rows,
        cand,
        partner,
        is_partner,
        ~(cand | is_partner | stray),
        0x600 + node,
        b0 == _ABORT,
        stray,
        Gathered(d, t, cid),
    )


def _rows(data: np.ndarray, at: np.ndarray) -> np.ndarray:
    """data[at] for (n, 8) payload rows: np.take is ~10x numpy's 2-D fancy indexing here."""
    return np.take(data, at, axis=0)


def py_round(v: np.ndarray, ndigits: int) -> np.ndarray:
    """Python's round(x, ndigits) of each value, as numpy where it provably agrees.

    numpy rounds the float product x * 10**n; Python rounds the exact decimal
    value of x. They can only choose differently when the product lies within a
    few ulps of a half, so those (rare) values are rounded by Python itself.
    """
    scale = 10.0**ndigits
    p = v * scale
    out = np.rint(p) / scale
    frac = np.abs(p - np.trunc(p))
    with np.errstate(invalid="ignore"):
        tol = np.maximum(1e-6, 8.0 * np.abs(np.spacing(p)))
        risky = ~(np.abs(frac - 0.5) >= tol) | ~(np.abs(p) < 2.0**52)
    if risky.any():
        idx = np.flatnonzero(risky)
        out[idx] = [round(x, ndigits) for x in v[idx].tolist()]
    return out


def _rounded_latency(dt: np.ndarray) -> np.ndarray:
    """round(round(dt * 1000, 6), 3) exactly as Python computes it, column-wise."""
    return py_round(py_round(np.asarray(dt, np.float64) * 1000.0, 6), 3)


def pair_columns(fb, a: np.ndarray, b: np.ndarray, rows: np.ndarray | None = None) -> SdoColumns:
    """What summary, timing and the network model read of taken pairs, as columns.

    `fb` a FrameBatch (a, b its rows) or a plan's `Gathered` (a, b positions in it, and
    `rows` the batch row of each position)."""
    da, db = _rows(fb.data, a), _rows(fb.data, b)
    t0, t1 = fb.t[a], fb.t[b]
    return SdoColumns(
        row=np.asarray(b if rows is None else rows[b], np.int64),
        req_row=np.asarray(a if rows is None else rows[a], np.int64),
        node=fb.can_id[a].astype(np.int64) - 0x600,
        upload=da[:, 0] == _UPLOAD_REQ,
        index=da[:, 1].astype(np.int64) | (da[:, 2].astype(np.int64) << 8),
        subindex=da[:, 3].astype(np.int64),
        ok=db[:, 0] != _ABORT,
        latency=_rounded_latency(t1 - t0),
        t=t1.astype(np.float64),
    )


def pair_records(
    fb,
    a: np.ndarray,
    b: np.ndarray,
    object_info: ObjectInfo | None,
    latency: np.ndarray | None = None,
) -> list[dict]:
    """Records of taken pairs, exactly as the tracker makes them, built from columns."""
    return pair_record_columns(fb, a, b, object_info, latency).records()


def pair_record_columns(
    fb,
    a: np.ndarray,
    b: np.ndarray,
    object_info: ObjectInfo | None,
    latency: np.ndarray | None = None,
    objects: tuple[np.ndarray, np.ndarray] | None = None,
) -> RecordColumns:
    """The records' fields of taken pairs as columns, values as the tracker makes them.

    Names and data types are looked up once per distinct (node, index, subindex),
    values decoded per data type as numpy columns. Aborted pairs (rare) go through
    `pair_outputs`. `objects`: np.unique(key, return_inverse=True) of the pairs' keys
    (node << 24 | index << 8 | subindex) when the caller made it already.
    """
    m = len(a)
    if m == 0:
        return RecordColumns.empty()
    da, db = _rows(fb.data, a), _rows(fb.data, b)
    upload = da[:, 0] == _UPLOAD_REQ
    aborted = db[:, 0] == _ABORT
    length = np.where(upload, _EXP_LEN[db[:, 0]], _EXP_LEN[da[:, 0]]).astype(np.int64)
    raw = np.ascontiguousarray(np.where(upload[:, None], db[:, 4:8], da[:, 4:8]))
    index_a = da[:, 1].astype(np.int64) | (da[:, 2].astype(np.int64) << 8)
    node_a = fb.can_id[a].astype(np.int64) - 0x600
    t0, t1 = fb.t[a], fb.t[b]
    ok = ~aborted
    any_abort = not bool(ok.all())
    data_len = np.where(ok, length, 0)
    names = np.full(m, None, object)
    values = np.full(m, None, object)
    name_code = np.zeros(m, np.int64)
    name_labels: list = [None]
    # the values as int64 while every one decoded is an int (else None): value_none marks None
    value_int: np.ndarray | None = np.zeros(m, np.int64)
    value_none = np.ones(m, bool)
    if object_info is not None:
        if objects is None:
            key = (node_a << 24) | (index_a << 8) | da[:, 3]
            objects = np.unique(key, return_inverse=True)
        uniq, inv = objects
        inv = inv.ravel()
        infos = [object_info(k >> 24, (k >> 8) & 0xFFFF, k & 0xFF) for k in uniq.tolist()]
        known = np.array([i is not None for i in infos], bool)
        if known.any():
            name_labels = [i[0] if i else None for i in infos]
            name_code = inv.astype(np.int64)
            names[:] = np.array(name_labels, object)[inv]
            dtype_of = np.array([i[1] if i else -1 for i in infos], np.int64)[inv]
            dtype_of[~known[inv] | aborted] = -1
            for code in sorted(set(dtype_of.tolist())):
                if code >= 0:
                    sel = np.flatnonzero(dtype_of == code)
                    values[sel] = decode_column(raw[sel], length[sel], code)
                    got = (
                        None
                        if value_int is None
                        else decode_int_column(raw[sel], length[sel], code)
                    )
                    if got is None:
                        value_int = None
                    else:
                        value_int[sel] = got[0]
                        value_none[sel] = got[1]
    words = _words_column(node_a, index_a, da[:, 3], values, names, raw, data_len, object_info)
    latency = _rounded_latency(t1 - t0) if latency is None else np.asarray(latency, np.float64)
    arrays = {
        "t_start": t0.astype(np.float64, copy=False),
        "t": t1.astype(np.float64, copy=False),
        "latency_ms": latency,
        "node": node_a,
        "index": index_a,
        "subindex": da[:, 3].astype(np.int64),
        "size": length,
        "upload": upload,
        "value": values,
        "name": names,
        "words": words,
        "raw": raw,
        "data_len": data_len,
        "name_code": name_code,
    }
    if value_int is not None:
        arrays["value_int"] = value_int
        arrays["value_none"] = value_none | aborted
    done: dict[int, dict] = {}
    if any_abort:
        for k in np.flatnonzero(aborted).tolist():
            done[k] = pair_outputs(fb, int(a[k]), int(b[k]), int(node_a[k]), object_info)[2]
    return RecordColumns(arrays, done, name_labels)


def _words_column(node, index, sub, values, names, raw, data_len, object_info) -> np.ndarray:
    """The `words` of each record: worded per distinct object and data, only for the
    objects that have words (communication objects, named CiA 402 words); None elsewhere."""
    m = len(node)
    out = np.full(m, None, object)
    if m == 0:
        return out
    # expedited data (4 bytes at most) is never guessed to be text (visible_string)
    maybe = ((index >= 0x1000) & (index <= 0x1FFF)) | np.isin(index, _WORDED)
    at = np.flatnonzero(maybe & (data_len > 0))
    if at.size == 0:
        return out
    word = raw[at].astype(np.int64) @ np.array([1, 1 << 8, 1 << 16, 1 << 24], np.int64)
    key = np.stack([node[at], index[at], sub[at], word, data_len[at]], axis=1)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    texts = [
        sdo_words(
            int(node[k]),
            int(index[k]),
            int(sub[k]),
            values[k],
            raw[k, : data_len[k]].tobytes(),
            names[k],
            object_info,
        )
        for k in at[first].tolist()
    ]
    out[at] = np.array(texts + [None], object)[:-1][inv.reshape(-1)]
    return out


_STRAY_COMMAND = {
    _SCS_UPLOAD: "initiate_upload_response",
    _SCS_DOWNLOAD: "initiate_download_response",
}


def stray_notes(fb, rows: np.ndarray) -> list[dict]:
    """Notes of initiate responses on an idle channel, as the tracker writes them
    (`SdoTracker._unexpected` with no transfer: the frame changes nothing)."""
    d = _rows(fb.data, rows)
    index = (d[:, 1].astype(np.int64) | (d[:, 2].astype(np.int64) << 8)).tolist()
    out = []
    for scs, i, s in zip((d[:, 0] >> 5).tolist(), index, d[:, 3].tolist(), strict=True):
        command = _STRAY_COMMAND[scs]
        out.append(
            {
                "role": command.replace("_", " "),
                "command": command,
                "index": i,
                "subindex": s,
                "sdo_problem": f"{command} with no transfer in progress",
            }
        )
    return out


def pair_outputs(
    fb, row_req: int, row_resp: int, node: int, object_info: ObjectInfo | None
) -> tuple[dict, dict, dict, str]:
    """(request note, response note, record, result) of one fast pair, as the tracker makes them."""
    req = fb.data[row_req].tobytes()
    resp = fb.data[row_resp].tobytes()
    index = req[1] | (req[2] << 8)
    sub = req[3]
    where = " " + sdo.object_text(index, sub)
    t0 = float(fb.t[row_req])
    t1 = float(fb.t[row_resp])
    upload = req[0] == _UPLOAD_REQ
    if upload:
        req_note = {"role": f"upload request{where}", "command": "initiate_upload_request"}
        data = b""
    else:
        size = f", {_EXP_LEN[req[0]]} bytes" if req[0] & sdo.SIZE_INDICATED else ""
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
        text = sdo.abort_text(code)
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
        "words": sdo_words(node, index, sub, value, bytes(data), name, object_info)
        if result == "ok"
        else None,
        "frames": 2,
        "cob_ids": [0x600 + node, 0x580 + node],
    }
    return req_note, resp_note, record, result
