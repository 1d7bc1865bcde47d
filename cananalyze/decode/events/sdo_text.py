"""The event-log text of an SDO transfer: per record, and as columns for the fast path.

A polled bus makes hundreds of thousands of SDO events; an f-string each was the
largest piece of Python left on the export's decoding thread (0.5 s per 10M
frames of generated traffic). `sdo_messages` builds the usual texts, an ok
expedited transfer with an integer value, as byte columns (`bytecols`) and
formats only the rest one by one with `sdo_message`, which stays the definition.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.columns import bytecols
from cananalyze.protocol.sdo import object_text

U64 = 0xFFFFFFFFFFFFFFFF
_LABELS = bytecols.padded_table([b"", b" = ", b" data "])  # no value or data, value, data
_OPEN_HEX = bytecols.padded_table([b"", b" (0x"])


SHOWN_BYTES = 32  # data bytes (and string characters x2) a text line shows of a transfer


def shown_data(data: str, size: bool = True) -> str:
    """Hex `data` as a text line shows it: the first SHOWN_BYTES bytes then "...", and
    with `size` the whole length. A 1 MB program download (0x1F50) was a 2 MB line in
    `decode` and in every event log; the SDO table and JSONL keep all of it."""
    if len(data) <= 2 * SHOWN_BYTES:
        return data
    return data[: 2 * SHOWN_BYTES] + (f"... ({len(data) // 2} bytes)" if size else "...")


def shown_text(value: str) -> str:
    """A string value as a text line shows it: at most 2 x SHOWN_BYTES characters."""
    return value if len(value) <= 2 * SHOWN_BYTES else value[: 2 * SHOWN_BYTES] + "..."


def sdo_message(direction, index, sub, name, result, value, data, abort, detail) -> str:
    """The event text of one SDO record, from its fields (one implementation for dicts and columns)."""
    return sdo_head(direction, index, sub, name) + sdo_tail(result, value, data, abort, detail)


def sdo_head(direction, index, sub, name) -> str:
    direction = direction or "transfer"  # an abort whose start is not in the log
    if isinstance(index, int) and isinstance(sub, int):
        text = f"SDO {direction} {object_text(index, sub)}"
    else:
        text = f"SDO {direction}"
    return f"{text} {name}" if name else text


def sdo_tail(result, value, data, abort, detail) -> str:
    ok = result == "ok"
    if ok:
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 9:
            text = f" = {value} (0x{value & U64:X}) ok"  # as the text output shows it
        elif isinstance(value, str):
            text = f" = {shown_text(value)} ok"
        elif value is not None:
            text = f" = {value} ok"
        elif data:
            text = f" data {shown_data(data)} ok"
        else:
            text = " ok"
    else:
        text = f" {result}"
    if abort:
        text += f": {abort}"
    elif not ok and detail:
        text += f": {detail}"
    return text


def sdo_messages(fields) -> list[str] | None:
    """`sdo_message` of each of the fast path's records (`RecordColumns`), built as
    columns; None when some decoded value is not an integer (the caller then goes
    record by record)."""
    a = fields.arrays
    if "value_int" not in a:
        return None
    n = len(fields)
    upload, index, sub = a["upload"], a["index"], a["subindex"]
    labels = fields.name_labels
    # the head, once per object, direction and name
    key = ((index * 256 + sub) * 2 + upload) * len(labels) + a["name_code"]
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    heads = [
        sdo_head("upload" if upload[i] else "download", int(index[i]), int(sub[i]), labels[c])
        for i, c in zip(first.tolist(), a["name_code"][first].tolist(), strict=True)
    ]
    head = bytecols.padded_table([h.encode() for h in heads])[inv.reshape(-1)]
    # the tail: " = v (0xV) ok", " = v ok", " data hex ok" or " ok"; a block no row
    # needs is left out (a polled bus's answers are often all data, or all values)
    v, none = a["value_int"], a["value_none"]
    wide = ~none & (np.abs(v) > 9)
    has_data = none & (a["data_len"] > 0)
    label = _LABELS[np.where(none, np.where(has_data, 2, 0), 1)]
    parts = [head, label]
    if has_data.any():
        parts.append(bytecols.hex_bytes(a["raw"], np.where(has_data, a["data_len"], 0)))
    if not none.all():
        dec = bytecols.decimal(v)
        dec[none] = bytecols.PAD
        parts.append(dec)
    if wide.any():
        hx = bytecols.hex_upper(v)
        hx[~wide] = bytecols.PAD
        close_hex = np.where(wide, ord(")"), bytecols.PAD).astype(np.uint8)[:, None]
        parts += [_OPEN_HEX[wide.astype(np.intp)], hx, close_hex]
    parts.append(bytecols.repeat(b" ok", n))
    messages = bytecols.joined_rows(parts, n)
    for k, rec in fields.held.items():  # held records (aborted, the tracker's) word their own
        messages[k] = record_message(rec)
    return messages


def record_message(rec: dict) -> str:
    """The event text of one SDO record dict; a CANopen FD USDO transfer's says USDO."""
    text = sdo_message(
        rec.get("direction"),
        rec.get("index"),
        rec.get("subindex"),
        rec.get("name"),
        rec.get("result", "?"),
        rec.get("value"),
        rec.get("data"),
        rec.get("abort_text"),
        rec.get("detail"),
    )
    if str(rec.get("protocol") or "").startswith("usdo"):
        text = "U" + text
    return text
