"""A row's fields as one dict: the stateless decode of its service, then the stateful notes
and its PDO signals. The row-by-row outputs (text, JSONL, the live dashboard) read this."""

from __future__ import annotations

from cananalyze.core.frames import FLAG_RTR
from cananalyze.core.records import DecodedBatch
from cananalyze.devices.words import word_fields
from cananalyze.protocol.fields import frame_fields


def row_fields(batch: DecodedBatch, i: int) -> dict:
    """All service fields of row i: stateless decode, then the stateful notes."""
    f = frame_fields(
        int(batch.service[i]),
        batch.frames.payload(i),
        bool(batch.frames.flags[i] & FLAG_RTR),
        int(batch.frames.can_id[i]),
    )
    lazy = batch.row_index()
    if lazy is not None:
        block, pos, shared, _ = lazy
        b = int(block[i])
        if b >= 0:
            sb = batch.signals[b]
            p = int(pos[i])
            f["signals"] = {k: v[p].item() for k, v in sb.columns.items()}
            f["units"] = {k: u for k, u in sb.units.items() if u}
            if sb.choices:
                f["labels"] = _labels(f["signals"], sb.choices)
            if sb.pdo[:4] not in ("tpdo", "rpdo"):
                f["message"] = sb.pdo  # a DBC message on a non-PDO identifier
            if sb.words:  # a CiA 402 drive's statusword, controlword, modes as data
                f["drive"] = {k: word_fields(i, int(sb.columns[k][p])) for k, i in sb.words.items()}
        s = int(shared[i])
        if s >= 0:
            f.update(batch.row_notes[s][1])
    note = batch.notes.get(i)
    if note:
        if note.get("command") == "block_segment":
            f = {}  # no command specifier: the initiate layout's fields would be made up
        f.update(note)
    return f


def _labels(values: dict, choices: dict[str, dict[int, str]]) -> dict[str, str]:
    """The value-table names of a row's signals that have one (a DBC's VAL_)."""
    out = {}
    for name, table in choices.items():
        v = values.get(name)
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        if isinstance(v, int) and v in table:
            out[name] = table[v]
    return out
