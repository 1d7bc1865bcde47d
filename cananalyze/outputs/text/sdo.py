"""The text output's SDO record lines built as byte columns.

A polled bus puts an expedited request and its answer on a few percent of its
frames (290k pairs in 10M generated frames). Written one by one, their record
lines were a third of `decode -o`'s decoding thread. Here each record's
"    └─ <record>" line comes from the batch's one record type (`RecordColumns`) in a
few numpy passes (the pairs' frame roles: `decode/sdo/roles`). `format_record`
stays the definition: the records the columns do not express (held: aborted, the
tracker's), a value that is not an integer, a negative latency are worded by it,
and a test compares every text with it.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.sdo.fastpath import py_round
from cananalyze.decode.sdo.lazynotes import LazyNotes
from cananalyze.outputs.text.records import format_record
from cananalyze.protocol.sdo import object_text

_VALUE = bytecols.padded_table([b"", b"data "])
_OPEN_HEX = bytecols.padded_table([b"", b" (0x"])
_DASH = bytecols.padded_table([b"", b"-"])


def fast_pairs(batch: DecodedBatch) -> tuple | None:
    """(fields, the fast part) of the batch's fast pairs when their frame notes are
    still unwritten and only theirs are: then no one has read or changed them, and
    they are what `pair_notes` would write, so their texts come from the columns.
    Else None (the caller reads the notes as they are)."""
    part = batch.records.fast_part()
    notes = batch.notes
    if part is None or not isinstance(notes, LazyNotes):
        return None
    pending = notes.pending_rows()
    cols = part.cols
    if pending is None or not np.array_equal(
        pending, np.unique(np.concatenate((cols.req_row, cols.row)))
    ):
        return None
    return part.fields(), part


def record_lines(fields) -> list[bytes]:
    """ "    └─ " + format_record(record) + "\n" of every record (`RecordColumns`, all of a
    batch's transfers), columnar where it can be, the held records by `format_record`."""
    m = len(fields)
    a = fields.arrays
    by_python = np.zeros(m, bool)
    by_python[list(fields.held)] = True
    if "value_int" not in a:  # some value is a float, bool or text: record by record
        by_python[:] = True
    by_python |= a["words"] != None  # noqa: E711 (elementwise): worded values are rare
    lat = a["latency_ms"]
    with np.errstate(invalid="ignore"):
        tenths = np.rint(py_round(np.where(lat >= 0, lat, 0.0), 1) * 10.0)
    by_python |= ~(lat >= 0) | ~(tenths < 2.0**52)
    if by_python.all():
        lines = [b""] * m
    else:
        lines = _columnar_lines(fields, np.where(by_python, 0, tenths).astype(np.int64), m)
    for j in np.flatnonzero(by_python).tolist():
        lines[j] = ("    └─ " + format_record(fields.record(j)) + "\n").encode()
    return lines


def _columnar_lines(fields, tenths: np.ndarray, m: int) -> list[bytes]:
    a = fields.arrays
    labels = fields.name_labels
    node, index, sub, upload, code = (
        a["node"],
        a["index"],
        a["subindex"],
        a["upload"],
        a["name_code"],
    )
    # "    └─ node N SDO read 0x1018:01 Name expedited -> ok: ", once per distinct head
    key = (((node * 65536 + index) * 256 + sub) * 2 + upload) * len(labels) + code
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    heads = []
    for i in first.tolist():
        name = labels[int(code[i])]
        what = "read" if upload[i] else "write"
        obj = object_text(int(index[i]), int(sub[i]))
        heads.append(
            f"    └─ node {int(node[i])} SDO {what} {obj}"
            f"{' ' + name if name else ''} expedited -> ok: ".encode()
        )
    head = bytecols.padded_table(heads)[inv.reshape(-1)]
    # the value: "v", "v (0xV)" or "data <hex>" ("data -" when there are no bytes)
    v, none = a["value_int"], a["value_none"]
    wide = ~none & (np.abs(v) > 9)
    dec = bytecols.decimal(v)
    dec[none] = bytecols.PAD
    hx = bytecols.hex_upper(v)
    hx[~wide] = bytecols.PAD
    close_hex = np.where(wide, ord(")"), bytecols.PAD).astype(np.uint8)[:, None]
    data = bytecols.hex_bytes(a["raw"], np.where(none, a["data_len"], 0))
    dash = _DASH[(none & (a["data_len"] == 0)).astype(np.intp)]
    size = bytecols.decimal(a["size"])
    parts = [head, _VALUE[none.astype(np.intp)], data, dash, dec, _OPEN_HEX[wide.astype(np.intp)]]
    parts += [
        hx,
        close_hex,
        bytecols.repeat(b" (", m),
        size,
        bytecols.repeat(b" bytes), latency ", m),
    ]
    parts += [
        bytecols.decimal(tenths // 10),
        bytecols.repeat(b".", m),
        (48 + tenths % 10).astype(np.uint8)[:, None],
    ]
    parts += [bytecols.repeat(b" ms\n", m)]
    return bytecols.row_bytes(*bytecols.compact(parts, m, with_ends=True))
