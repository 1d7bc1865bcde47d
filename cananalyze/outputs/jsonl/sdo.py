"""The JSONL fields of the SDO fast path's frames, built as byte columns.

An expedited request and its answer are a few percent of a polled bus's frames
(600k of 10M generated ones) and were the largest part of the JSONL writer's
Python: `batch.fields` writes each frame's note, `describe_sdo` parses the frame
again and `json.dumps` writes both. A frame's fields are `sdo_fields` of its
bytes (their keys fixed by the command byte) followed by the pair's note (`role`,
which `sdo_text` builds as columns). So per command byte one frame is written by
Python; its keys give the group's fixed text, its values are checked against the
columns built for it, and the group's other frames take the same columns.
Aborted pairs, and any group whose check fails, stay with Python.
"""

from __future__ import annotations

import json

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.core.sdo_records import RecordColumns, hex_texts
from cananalyze.decode.sdo.fastpath import pair_outputs
from cananalyze.decode.sdo.roles import pair_roles
from cananalyze.outputs.jsonl.encode import dumps
from cananalyze.protocol.sdo import fields as sdo_fields

_EXPEDITED = ("expedited", "size_indicated", "n", "size", "sdo_data")


def pair_fields(fb, fields, fast, fields_text) -> list[tuple[np.ndarray, list[bytes]]]:
    """(batch rows, their fields text) for the fast pairs' frames, request and answer
    rows, a group per command byte; `fields_text` is how the writer words a fields
    dict (the check compares with it)."""
    req_role, resp_role = pair_roles(fb, fields, fast.cols.req_row, fast.cols.row, b"")
    a = fields.arrays
    ok = np.ones(len(fields), bool)
    ok[list(fields.held)] = False
    out = []
    for is_req, rows, roles in (
        (True, fast.cols.req_row, req_role[:, 4:]),  # without "SDO "
        (False, fast.cols.row, resp_role[:, 4:]),
    ):
        b0 = fb.data[rows, 0]
        for code in np.unique(b0[ok]).tolist():
            js = np.flatnonzero(ok & (b0 == code))
            block = _group(fb, fast, a, is_req, rows, roles, js, fields_text)
            if block is not None:
                out.append((rows[js], block))
    return out


def _group(fb, fast, a, is_req, rows, roles, js, fields_text) -> list[bytes] | None:
    j = int(js[0])
    row = int(rows[j])
    note = pair_outputs(
        fb, int(fast.cols.req_row[j]), int(fast.cols.row[j]), int(a["node"][j]), None
    )
    f = sdo_fields(fb.payload(row), is_req)
    f.update(note[0] if is_req else note[1])
    keys = [k for k in f if k not in _EXPEDITED]
    if keys != ["cs", "command", "index", "subindex", "role"]:
        return None
    m = len(js)
    parts = [
        bytecols.repeat(
            f',"cs":{json.dumps(f["cs"])},"command":{json.dumps(f["command"])},"index":', m
        )
    ]
    parts += [bytecols.decimal(a["index"][js]), bytecols.repeat(',"subindex":', m)]
    parts += [bytecols.decimal(a["subindex"][js])]
    if "expedited" in f:
        if [k for k in f if k in _EXPEDITED] != [k for k in _EXPEDITED if k in f]:
            return None
        head = "".join(f",{json.dumps(k)}:{json.dumps(f[k])}" for k in _EXPEDITED[:-1] if k in f)
        size = len(f["sdo_data"]) // 2
        payload = fb.data[rows[js], 4:8]
        parts += [bytecols.repeat(head + ',"sdo_data":"', m)]
        parts += [bytecols.hex_bytes(payload, np.full(m, size)), bytecols.repeat('"', m)]
    parts += [bytecols.repeat(',"role":"', m), roles[js], bytecols.repeat('"', m)]
    blob, ends = bytecols.compact(parts, m, with_ends=True)
    if blob[: int(ends[0])] != fields_text(f):  # the group's fixed text, checked on its first frame
        return None
    return bytecols.row_bytes(blob, ends)


# the line of an ok expedited pair as `dumps(RecordColumns.record(j))` writes it, key for key
_PAIR_LINE = (
    '{"kind":"sdo","t_start":%s,"t":%s,"latency_ms":%s,"node":%d,"direction":"%s",'
    '"protocol":"expedited","index":%d,"subindex":%d,"size":%d,"data":"%s","value":%s,'
    '"name":%s,"result":"ok","abort_code":null,"abort_text":null,"detail":null,"words":%s,'
    '"frames":2,"cob_ids":[%d,%d]}\n'
)


def record_lines(fields: RecordColumns) -> list[bytes]:
    """`dumps(record) + "\\n"` of every transfer of a batch (`RecordColumns`, by
    position): the fast path's pairs by one format each from the columns (a dict and a
    `json.dumps` each were a tenth of a JSONL decode of a polled bus), the held records
    dumped."""
    m = len(fields)
    if m == 0:
        return []
    a = fields.arrays
    t_start, t, lat = (_json_floats(a[c]) for c in ("t_start", "t", "latency_ms"))
    node, index, sub, size = (a[c].tolist() for c in ("node", "index", "subindex", "size"))
    direction = np.where(a["upload"], "upload", "download").tolist()
    data = hex_texts(a["raw"], a["data_len"])
    names = [dumps(x) for x in fields.name_labels]
    name = [names[c] for c in a["name_code"].tolist()]
    value = _json_values(a["value"].tolist())
    words = _json_values(a["words"].tolist())
    held = fields.held
    return [
        (dumps(held[j]) + "\n").encode()
        if j in held
        else (
            _PAIR_LINE
            % (
                t_start[j],
                t[j],
                lat[j],
                node[j],
                direction[j],
                index[j],
                sub[j],
                size[j],
                data[j],
                value[j],
                name[j],
                words[j],
                0x600 + node[j],
                0x580 + node[j],
            )
        ).encode()
        for j in range(m)
    ]


def _json_floats(v: np.ndarray) -> list[str]:
    """json.dumps of each float: repr, or NaN / Infinity / -Infinity."""
    return (
        [dumps(x) for x in v.tolist()]
        if not np.isfinite(v).all()
        else list(map(float.__repr__, v.tolist()))
    )


def _json_values(values: list) -> list[str]:
    """json.dumps of each value (as inside the record's dict); a text once per distinct
    text value, a float each time (-0.0 == 0.0 as a key)."""
    memo: dict[str, str] = {}
    out = []
    for v in values:
        kind = type(v)
        if v is None:
            out.append("null")
        elif kind is int:
            out.append(int.__repr__(v))
        elif kind is str:
            text = memo.get(v)
            if text is None:
                text = memo[v] = dumps(v)
            out.append(text)
        else:  # floats, numpy scalars, bytes, a dict of words: as the dict's dumps does
            out.append(dumps(v))
    return out
