"""`--format jsonl` for a whole batch at once: the frame lines built as byte columns.

A `json.dumps` of a dict per frame ran at ~120k lines/s: a 10M-frame log took
85 s. Here what every line holds (time, channel, id, DLC, payload, flags,
service, node, PDO) and the service fields that depend only on a row's service
and first byte, or on its PDO signals, are NUL-padded byte columns compacted in
one pass (`bytecols`). `jsonl.frame_record` and `dumps` stay the definition:
the fields of the other rows (notes, SDO, EMCY, NMT, shared notes, values
Python words its own way) are still the dicts `batch.fields` gives, dumped one
by one, and so is every record.

Floats: pyarrow's shortest round-trip text is Python's `repr` wherever it has no
exponent and 1e-4 <= |v| < 1e16, once ".0" is added to whole numbers (checked
on 12M random values); the others are written by `repr`.
"""

from __future__ import annotations

import json

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RECONSTRUCTED, FLAG_RTR
from cananalyze.core.records import DecodedBatch
from cananalyze.devices.words import fields_column
from cananalyze.outputs.fields import row_fields
from cananalyze.outputs.jsonl.encode import clean, clean_fields, dumps
from cananalyze.outputs.jsonl.records import jsonl_record_lines
from cananalyze.outputs.jsonl.sdo import pair_fields
from cananalyze.outputs.text.sdo import fast_pairs
from cananalyze.outputs.text.writer import _KEYED, Rendered, _key_groups, _padded_table
from cananalyze.protocol.fields import frame_fields
from cananalyze.protocol.services import SERVICE_NAMES, Service
from cananalyze.runtime.speedups import C

# keyed rows whose fields read the first data byte (boot-up's state too, unlike its text)
_BYTE = np.zeros(256, bool)
_BYTE[
    [
        Service.SYNC,
        Service.HEARTBEAT,
        Service.BOOTUP,
        Service.GUARD_RESPONSE,
        Service.LSS_MASTER,
        Service.LSS_SLAVE,
    ]
] = True
_SERVICE = _padded_table([json.dumps(name).encode() for name in SERVICE_NAMES])
_FLAGS = [
    (FLAG_RTR, _padded_table([b"", b',"rtr":true'])),
    (FLAG_EXT, _padded_table([b"", b',"ext":true'])),
    (FLAG_ERR, _padded_table([b"", b',"error":true'])),
    (FLAG_FD, _padded_table([b"", b',"fd":true'])),
    (FLAG_RECONSTRUCTED, _padded_table([b"", b',"reconstructed":true'])),
]


def render(batch: DecodedBatch, mask: np.ndarray | None) -> Rendered | None:
    """The batch's JSONL (frames, each followed by its records; then the records of
    rows not shown), or None for batches the per-row writer takes (long FD payloads)."""
    fb = batch.frames
    if fb.long_data:
        return None
    sel = np.arange(len(fb)) if mask is None else np.flatnonzero(mask)
    n = sel.size
    pairs = fast_pairs(batch) if mask is None else None  # before anything reads the notes
    records = jsonl_record_lines(batch)
    by_row: dict[int, list[bytes]] = {}
    for row, line in records:
        by_row.setdefault(row, []).append(line)
    shown = np.zeros(len(fb), bool)
    shown[sel] = True
    tail = b"".join(line for row, line in records if not (0 <= row < len(fb) and shown[row]))
    if n == 0:
        return Rendered([], 0, np.zeros(0, np.int64), [], tail)
    flags, svc, dlc, data = fb.flags[sel], batch.service[sel], fb.dlc[sel], fb.data[sel]
    node, pdo = batch.node[sel], batch.pdo[sel]
    rtr = (flags & FLAG_RTR) != 0
    parts = [bytecols.repeat(b'{"kind":"frame","t":', n), _floats(fb.t[sel])]
    channels = [json.dumps(fb.channel_label(c)).encode() for c in range(_channels(fb))]
    parts += [bytecols.repeat(b',"channel":', n), _padded_table(channels)[fb.channel[sel]]]
    parts += [bytecols.repeat(b',"can_id":', n), bytecols.decimal(fb.can_id[sel])]
    parts += [bytecols.repeat(b',"dlc":', n), bytecols.decimal(dlc)]
    shown_bytes = np.where(rtr, 0, np.minimum(dlc, 8))
    parts += [
        bytecols.repeat(b',"data":"', n),
        bytecols.hex_bytes(data, shown_bytes),
        bytecols.repeat(b'"', n),
    ]
    seen = int(np.bitwise_or.reduce(flags))  # a flag no row has: no column
    parts += [table[((flags & flag) != 0).astype(np.intp)] for flag, table in _FLAGS if seen & flag]
    parts += [
        bytecols.repeat(b',"service":', n),
        _SERVICE[svc],
        bytecols.repeat(b',"node":', n),
        _node(node),
    ]
    has_pdo = pdo != 0
    pdo_text = bytecols.decimal(pdo)
    pdo_text[~has_pdo] = bytecols.PAD
    parts += [_padded_table([b"", b',"pdo":'])[has_pdo.astype(np.intp)], pdo_text]

    # the service fields: by group where a few bytes decide them, per signal block, else Python
    notes = batch.notes
    noted = np.zeros(n, bool)
    written = len(notes) if pairs is None else dict.__len__(notes)  # the pairs' stay unwritten
    if written:
        noted_rows = np.zeros(len(fb), bool)
        noted_rows[np.fromiter(dict.keys(notes), np.int64, written)] = True
        noted = noted_rows[sel]
    lazy = batch.row_index()
    in_block = np.full(n, -1, np.int32) if lazy is None else lazy[0][sel]
    shared = np.full(n, -1, np.int32) if lazy is None else lazy[2][sel]
    pending = np.zeros(n, bool)  # the fast pairs' rows: notes still to be written
    if pairs is not None:
        pending[np.concatenate((pairs[1].cols.req_row, pairs[1].cols.row))] = True
    plain = ~noted & ~pending & (shared < 0)
    keyed = _KEYED[svc] & plain & (in_block < 0)
    inv, first_at = _key_groups(svc, pdo, rtr, dlc, data, keyed, byte_matters=_BYTE)
    texts = [b""]
    for i in first_at[1:].tolist():
        fields = frame_fields(int(svc[i]), fb.payload(int(sel[i])), bool(rtr[i]))
        texts.append(_fields_text(fields))
    fields_col = [(np.arange(n), _padded_table(texts)[inv])]
    done = keyed.copy()
    for k, sb in enumerate(batch.signals):
        rows = np.flatnonzero(plain & (in_block == k))
        if rows.size:
            got = _signal_text(sb, lazy[1][sel[rows]])
            if got is not None:
                fields_col.append((rows, got))
                done[rows] = True
    # the longer fields of the few other rows go in before their "}\n" (`spliced`): as
    # a column they would widen it for every row (the SDO fields are ~200 bytes)
    spliced: dict[int, bytes] = {}
    if pairs is not None:  # (mask None: batch rows are positions)
        sdo = (svc == Service.SDO_REQUEST) | (svc == Service.SDO_RESPONSE)
        for rows, texts in pair_fields(fb, pairs[0], pairs[1], _fields_text):
            # fields that are the pair's alone: an SDO frame, no other notes or signals
            free = ~noted[rows] & (shared[rows] < 0) & (in_block[rows] < 0) & sdo[rows]
            taken = zip(rows.tolist(), texts, free.tolist(), strict=True)
            spliced.update((row, text) for row, text, ok in taken if ok)
            done[rows[free]] = True
    slow = np.flatnonzero(~done)  # notes, EMCY, NMT, other SDO...: their fields by Python
    # a row with no notes and no signals has the fields of its frame alone: one text per
    # distinct frame (a node's repeated EMCY "no error", its NMT commands)
    alone = (plain & (in_block < 0))[slow].tolist()
    memo: dict[tuple, bytes] = {}
    for i, row, bare in zip(slow.tolist(), sel[slow].tolist(), alone, strict=True):
        if not bare:
            spliced[i] = _fields_text(row_fields(batch, row))
            continue
        key = (int(svc[i]), int(fb.can_id[row]), bool(rtr[i]), fb.payload(row))
        text = memo.get(key)
        if text is None:
            text = memo[key] = _fields_text(row_fields(batch, row))
        spliced[i] = text
    width = max(m.shape[1] for _, m in fields_col)
    fields_m = np.zeros((n, width), np.uint8)
    for rows, m in fields_col:
        fields_m[rows, : m.shape[1]] = m
    parts += [fields_m, bytecols.repeat(b"}\n", n)]

    # the records after their frame's line
    records_after: dict[int, bytes] = {}
    if by_row:
        rec_rows = np.zeros(len(fb), bool)
        rec_rows[[r for r in by_row if 0 <= r < len(fb)]] = True
        for i in np.flatnonzero(rec_rows[sel]).tolist():
            records_after[i] = b"".join(by_row[int(sel[i])])
    after, inserts, back = [], [], []
    for i in sorted(spliced.keys() | records_after.keys()):
        for text, before in ((spliced.get(i), 2), (records_after.get(i), 0)):
            if text:
                after.append(i)
                inserts.append(text)
                back.append(before)  # 2: inside the line, before its "}\n"
    return Rendered(parts, n, np.asarray(after, np.int64), inserts, tail, back)


def _channels(fb) -> int:
    return max(int(fb.channel.max()) + 1 if len(fb) else 0, len(fb.channels))


def _node(node: np.ndarray) -> np.ndarray:
    """The node-ID, or null where there is none."""
    text = bytecols.decimal(np.where(node >= 0, node, 0))
    if text.shape[1] < 4:
        text = np.concatenate([text, np.zeros((len(node), 4 - text.shape[1]), np.uint8)], axis=1)
    none = node < 0
    text[none] = bytecols.PAD
    text[none, :4] = np.frombuffer(b"null", np.uint8)
    return text


def _fields_text(fields: dict) -> bytes:
    """',"k":v,...' of a row's fields, as `frame_record` adds them to its dict."""
    text = dumps(clean_fields(fields))[1:-1]
    return ("," + text).encode() if text else b""


def _signal_text(sb, pos: np.ndarray) -> np.ndarray | None:
    """',"signals":{...},"units":{...}' of a block's rows (`pos`: positions in the
    block), or None when a column is of a type only Python words."""
    m = len(pos)
    if sb.choices:
        return None  # value-table names ("labels"): the per-row way
    parts = []
    if sb.pdo[:4] not in ("tpdo", "rpdo"):  # a DBC message on a non-PDO identifier
        parts.append(bytecols.repeat((',"message":' + json.dumps(sb.pdo)).encode(), m))
    for j, (name, values) in enumerate(sb.columns.items()):
        v = np.asarray(values)[pos]
        if v.dtype.kind == "f":
            text = _floats(v)
        elif v.dtype.kind == "b":
            text = _padded_table([b"false", b"true"])[v.astype(np.intp)]
        elif v.dtype.kind == "i" or (v.dtype.kind == "u" and int(v.max(initial=0)) < 1 << 63):
            text = bytecols.decimal(v.astype(np.int64))
        else:
            return None
        head = (',"signals":{' if j == 0 else ",") + json.dumps(name, ensure_ascii=False) + ":"
        parts += [bytecols.repeat(head.encode(), m), text]
    units = dumps({k: clean(u) for k, u in sb.units.items() if u})
    parts.append(
        bytecols.repeat(
            (("}" if sb.columns else ',"signals":{}') + ',"units":' + units).encode(), m
        )
    )
    for j, (name, index) in enumerate(sb.words.items()):  # one text per distinct value
        fields, inv = fields_column(index, np.asarray(sb.columns[name])[pos])
        head = (',"drive":{' if j == 0 else ",") + json.dumps(name) + ":"
        parts += [bytecols.repeat(head.encode(), m)]
        parts += [_padded_table([dumps(w).encode() for w in fields])[inv]]
    if sb.words:
        parts.append(bytecols.repeat(b"}", m))
    return bytecols.left_aligned(*bytecols.compact(parts, m, with_ends=True))


def _floats(v: np.ndarray) -> np.ndarray:
    """NUL-padded `repr` of each float, or null where not finite."""
    import pyarrow as pa

    from cananalyze.core.columns import arrow_build as ab
    from cananalyze.core.columns.json_text import Texts

    v = np.ascontiguousarray(v, np.float64)
    n = v.size
    compiled = getattr(C, "float_repr", None)
    if compiled is not None:  # one pass: time stamps from their digits, the rest by Arrow
        out = np.zeros((n, 24), np.uint8)
        todo = np.zeros(n, np.uint8)
        width = compiled(v, None, None, out, todo)
        rest = np.flatnonzero(todo)
        if rest.size:  # Arrow's text of those, mended where it is not repr's
            sub, t = v[rest], Texts.from_arrow(ab.cast(ab.numeric(v[rest]), pa.string()))
            part = np.zeros((rest.size, 24), np.uint8)
            width = max(width, compiled(sub, t.data, t.offsets, part, None))
            out[rest] = part
        return out[:, : max(width, 1)]
    # built from the buffer and cast by the kernel's name: pa.array imports pandas, and
    # pyarrow.compute its wrappers (0.2-0.3 s of a JSONL decode that needs neither)
    t = Texts.from_arrow(ab.cast(ab.numeric(v), pa.string()))
    lengths = t.lengths
    width = int(lengths.max()) + 2 if n else 2
    out = np.zeros((n, width), np.uint8)
    out[np.arange(width)[None, :] < lengths[:, None]] = t.data
    a = np.abs(v)
    usable = ((a >= 1e-4) & (a < 1e16)) | (v == 0)
    usable &= ~(out == ord("e")).any(axis=1)
    whole = usable & ~(out == ord(".")).any(axis=1)
    out[whole, lengths[whole]] = ord(".")
    out[whole, lengths[whole] + 1] = ord("0")
    for i in np.flatnonzero(~usable).tolist():
        x = float(v[i])
        text = (repr(x) if x == x and abs(x) != float("inf") else "null").encode()
        if len(text) > out.shape[1]:
            out = np.concatenate([out, np.zeros((n, len(text) - out.shape[1]), np.uint8)], 1)
        out[i] = bytecols.PAD
        out[i, : len(text)] = np.frombuffer(text, np.uint8)
    return out
