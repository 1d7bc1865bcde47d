"""`decode` text output: one aligned, candump-like line per frame plus its annotation.

Records (SDO transactions, findings) print as indented lines right after the
frame that completed them.

Logs run to tens of millions of lines, so lines are built column-wise: the
fixed part (time, channel, id, dlc, data, service, node) as a byte matrix padded
with NUL, and the annotation of rows whose text depends only on the service,
PDO number, RTR bit and first byte looked up per distinct key (computed once by
`annotation` itself, so the text cannot drift). Only rows with stateful notes,
records or free-form text (SDO, EMCY, TIME, NMT) get a Python line tail.
`lines_per_row` is the plain per-row writer, kept for odd batches and as the
reference the fast writer is tested against.
"""

from __future__ import annotations

import contextlib
from typing import TextIO

import numpy as np

from cananalyze.core.columns import bytecols as _bytecols
from cananalyze.core.columns.bytecols import HEX_UPPER as _HEXCHARS
from cananalyze.core.columns.bytecols import PAD as _PAD
from cananalyze.core.columns.bytecols import compact as _compact
from cananalyze.core.columns.bytecols import digits as _digits
from cananalyze.core.columns.bytecols import padded_table as _padded_table
from cananalyze.core.columns.numtext import g6_text, value_text
from cananalyze.core.frames import (
    FLAG_ERR,
    FLAG_EXT,
    FLAG_RECONSTRUCTED,
    FLAG_RTR,
    RECONSTRUCTED_MARK,
)
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.sdo.roles import pair_roles
from cananalyze.devices.words import word_column
from cananalyze.outputs import colour
from cananalyze.outputs.background import ByteSink
from cananalyze.outputs.fields import row_fields
from cananalyze.outputs.text.records import format_alone, format_record
from cananalyze.outputs.text.sdo import fast_pairs, record_lines
from cananalyze.pipeline.sink import Sink
from cananalyze.protocol import emcy as emcy_text
from cananalyze.protocol.fields import annotation, frame_fields
from cananalyze.protocol.services import SERVICE_NAMES, Service
from cananalyze.runtime import speedups

_HEX3 = [f"{i:02X} " for i in range(256)]
# before the annotation of a frame whose bytes the reader rebuilt from the log's text
_MARK = RECONSTRUCTED_MARK + " "
_MARK_COL = _padded_table([b"", _MARK.encode()])

# ANSI colours per service group, only on a terminal.
_COLOURS = colour.SERVICE
_RESET = colour.RESET


_SHOWN = np.arange(24)[None, :] < 3 * np.arange(9)[:, None]  # DLC -> which of 24 chars show
_SVC_COL = np.array([list(f"{name:<14} ".encode()) for name in SERVICE_NAMES], np.uint8)
# Services whose annotation is a function of (service, pdo, rtr, first byte or none).
_KEYED = np.zeros(256, bool)
_KEYED[
    [
        Service.OTHER,
        Service.SYNC,
        Service.TPDO,
        Service.RPDO,
        Service.HEARTBEAT,
        Service.BOOTUP,
        Service.GUARD_REQUEST,
        Service.GUARD_RESPONSE,
        Service.LSS_MASTER,
        Service.LSS_SLAVE,  # (not ERROR_FRAME: its classes are in the identifier)
        Service.ERRCTL_INVALID,
        Service.SRDO,
        Service.SRDO_INVERTED,
        Service.GFC,
    ]
] = True
_BYTE_MATTERS = np.zeros(256, bool)  # the first data byte changes the text
_BYTE_MATTERS[
    [Service.SYNC, Service.HEARTBEAT, Service.GUARD_RESPONSE, Service.LSS_MASTER, Service.LSS_SLAVE]
] = True
_LENGTH_MATTERS = np.zeros(256, bool)  # the text names the frame's length instead
_LENGTH_MATTERS[Service.ERRCTL_INVALID] = True


def _time_column(rel: np.ndarray) -> np.ndarray:
    """`f"{x:12.6f}"` of each value as a NUL-padded byte matrix.

    Rounded in numpy; rows whose rounding is in doubt (close to a half
    microsecond), negative or huge are formatted by Python and written in.
    """
    n = rel.size
    compiled = getattr(speedups.C, "time_text", None)
    if compiled is not None:  # the same rounding and doubt, one pass
        out = np.zeros((n, 40), np.uint8)
        width = compiled(np.ascontiguousarray(rel, np.float64), out)
        if width >= 0:
            return out[:, 40 - max(width, 12) :]
    v = rel * 1e6
    odd = ~(v >= 0) | np.signbit(v) | (v >= 1e12)
    vv = np.where(odd, 0.0, v)
    k = np.rint(vv)
    odd |= np.abs(vv - np.floor(vv) - 0.5) < 1e-3
    k = k.astype(np.int64)
    sec, frac = np.divmod(k, 1_000_000)
    w = max(1, len(str(int(sec.max())))) if n else 1
    fixed = []
    for i in np.flatnonzero(odd).tolist():
        fixed.append((i, f"{float(rel[i]):12.6f}".encode()))
    width = max([12, w + 7] + [len(x) for _, x in fixed])
    col = np.full((n, width), _PAD, np.uint8)
    ip = _digits(sec, w)
    # leading zeros of the integer part: spaces inside the 12-wide field, else nothing
    sec_len = np.ones(n, np.int64)
    for d in range(1, w):
        sec_len += sec >= 10**d
    pos = np.arange(w)[None, :]
    lead = pos < (w - sec_len)[:, None]
    ip = np.where(lead, np.where((width - 7 - w + pos) >= width - 12, 32, _PAD), ip)
    col[:, max(0, width - 12) : width - 7 - w] = 32
    col[:, width - 7 - w : width - 7] = ip
    col[:, width - 7] = ord(".")
    col[:, width - 6 :] = _digits(frac, 6)
    for i, x in fixed:
        col[i] = _PAD
        col[i, width - len(x) :] = np.frombuffer(x, np.uint8)
    return col


def _frame_columns(can_id, flags, dlc, data, rtr) -> np.ndarray:
    """Identifier, length and data columns (n, 39): one compiled pass, or numpy's."""
    n = can_id.size
    compiled = getattr(speedups.C, "frame_text", None)
    if compiled is not None and data.shape[1:] == (8,):  # (FrameBatch.data: 8 bytes a row)
        out = np.empty((n, 39), np.uint8)
        compiled(
            np.ascontiguousarray(can_id, np.uint32),
            np.ascontiguousarray(flags, np.uint8),
            np.ascontiguousarray(dlc, np.uint8),
            np.ascontiguousarray(data, np.uint8),
            out,
        )
        return out
    ident = np.empty((n, 10), np.uint8)
    for j in range(8):
        ident[:, j] = _HEXCHARS[(can_id >> (4 * (7 - j))) & 0xF]
    std = (flags & (FLAG_EXT | FLAG_ERR)) == 0
    ident[std, :5] = 32
    ident[:, 8:] = 32
    dlc_col = np.empty((n, 6), np.uint8)
    dlc_col[:, 0] = ord("[")
    tens = dlc // 10
    dlc_col[:, 1] = np.where(tens > 0, 48 + tens, _PAD)
    dlc_col[:, 2] = 48 + dlc % 10
    dlc_col[:, 3] = ord("]")
    dlc_col[:, 4:] = 32
    hx = np.empty((n, 8, 3), np.uint8)
    hx[:, :, 0] = _HEXCHARS[data >> 4]
    hx[:, :, 1] = _HEXCHARS[data & 0xF]
    hx[:, :, 2] = 32
    hx = hx.reshape(n, 24)
    # blanked past the DLC by the DLC's row of a mask table: half the time of a
    # boolean scatter over (n, 8, 3)
    np.copyto(hx, np.uint8(32), where=~_SHOWN[np.minimum(dlc, 8)])
    hx = hx[:, :23]
    hx[rtr] = np.frombuffer(b"remote request".ljust(23), np.uint8)
    return np.concatenate([ident, dlc_col, hx], axis=1)


class TextWriter(Sink):
    """Writes decoded batches as text lines (a pipeline sink, or called directly).

    With `background=True` and a UTF-8 text file with a binary buffer under it,
    each batch's lines are finished (compacted) and written by a worker thread
    while the caller decodes the next batch (`background.ByteSink`). `close()`
    waits for the worker and raises what it raised.
    """

    def __init__(
        self,
        out: TextIO,
        color: bool = False,
        t0: float | None = None,
        only_records: bool = False,
        background: bool = False,
        flush: bool = False,
    ) -> None:
        """`flush`: after every batch (live output, also into a pipe or a file)."""
        self.out = out
        self.flush = flush
        self.color = color
        self.t0 = t0
        self.only_records = only_records
        self._sink = ByteSink(out, background, "text-writer")

    def open(self, run) -> None:
        """Times count from the log's first frame, or are shown as logged (`--time abs`)."""
        super().open(run)
        if run.options.time == "abs":
            self.t0 = 0.0

    def write(self, batch: DecodedBatch, mask: np.ndarray | None = None) -> None:
        fb = batch.frames
        if self.t0 is None:
            run = getattr(self, "run", None)
            if run is not None and run.t0 is not None:
                self.t0 = run.t0  # the log's first frame, also when filters hide it
            elif len(fb):
                self.t0 = float(fb.t[0])
        t0 = self.t0 or 0.0
        if self.only_records or not len(fb) or not self._columnar_ok(batch):
            lines = lines_per_row(batch, mask, t0, self.color, self.only_records)
            if not lines:
                return
            if not self._sink.background:
                self.out.write("\n".join(lines) + "\n")
            else:
                self._sink.put(("\n".join(lines) + "\n").encode("utf-8"))
        else:
            self._sink.put(self._render(batch, mask, t0))
        if self.flush:
            self.out.flush()

    def close(self) -> None:
        """Wait for the worker, if any; re-raise its error here."""
        self._sink.close()

    def abort(self) -> None:
        with contextlib.suppress(Exception):
            self._sink.close()

    @staticmethod
    def _columnar_ok(batch: DecodedBatch) -> bool:
        """Whether every row fits the fixed columns (no long FD payloads, 3-digit nodes)."""
        fb = batch.frames
        if fb.long_data or (batch.node > 999).any():
            return False
        std = (fb.flags & (FLAG_EXT | FLAG_ERR)) == 0
        return not (fb.can_id[std] > 0xFFF).any()

    def _render(self, batch: DecodedBatch, mask: np.ndarray | None, t0: float) -> bytes | Rendered:
        fb = batch.frames
        sel = np.arange(len(fb)) if mask is None else np.flatnonzero(mask)
        n = sel.size
        # the SDO fast path's pairs: their frame notes unwritten, worded from columns
        pairs = fast_pairs(batch) if mask is None else None
        # every record's line from the batch's one record type, then the findings'
        recs = batch.records
        lines = record_lines(recs.fields()) if recs else []
        rows = list(recs.rows)
        found = list(batch.findings.pairs()) if len(batch.findings) else []
        if found:  # after the records, in their slots' order
            rows += [row for row, _ in found]
            lines += [("    └─ " + format_record(rec) + "\n").encode() for _, rec in found]
        by_row = _joined_by_row(rows, lines)
        shown = np.zeros(len(fb), bool)
        shown[sel] = True
        nrows = len(fb)
        at = np.asarray(rows, np.int64)
        alone = ~((at >= 0) & (at < nrows))  # records of rows not shown: after the batch
        alone[~alone] = ~shown[at[~alone]]
        tail_lines = [
            format_alone(recs.record(k) if k < len(recs) else found[k - len(recs)][1], t0)
            for k in np.flatnonzero(alone).tolist()
        ]
        if n == 0:
            return ("\n".join(tail_lines) + "\n").encode() if tail_lines else b""
        flags = fb.flags[sel]
        can_id = fb.can_id[sel]
        dlc = fb.dlc[sel]
        data = fb.data[sel]
        svc = batch.service[sel]
        node = batch.node[sel]
        pdo = batch.pdo[sel]
        rtr = (flags & FLAG_RTR) != 0
        parts: list[np.ndarray] = []
        colours = None
        if self.color:
            colours = [_COLOURS.get(name, "").encode() for name in SERVICE_NAMES]
            parts.append(_padded_table(colours)[svc])
        parts.append(_time_column(fb.t[sel] - t0))
        # channel, padded to 5 and a space
        names = [
            (f"  {fb.channel_label(c):<5} ").encode() for c in range(int(fb.channel.max()) + 1)
        ]
        parts.append(_padded_table(names)[fb.channel[sel]])
        parts.append(_frame_columns(can_id, flags, dlc, data, rtr))
        parts.append(np.full((n, 2), 32, np.uint8))
        parts.append(_SVC_COL[svc])
        node_col = np.full((n, 5), 32, np.uint8)
        has = node >= 0
        nd = np.where(has, node, 0).astype(np.int64)
        node_col[:, 0] = np.where(nd >= 100, 48 + nd // 100, 32)
        node_col[:, 1] = np.where(nd >= 10, 48 + (nd // 10) % 10, 32)
        node_col[:, 2] = np.where(has, 48 + nd % 10, 32)
        parts.append(node_col)

        # annotation: keyed rows from a table, PDO signal rows formatted per
        # column, other rows' text built in Python and scattered in, rows with
        # records spliced in after the compaction
        end = (_RESET if self.color else "") + "\n"
        endb = end.encode()
        noted = np.zeros(n, bool)
        notes = batch.notes
        # len() realises lazy notes once; the fast pairs' stay unwritten (texts from columns)
        written = len(notes) if pairs is None else dict.__len__(notes)
        if written:
            noted_rows = np.zeros(len(fb), bool)
            noted_rows[np.fromiter(dict.keys(notes), np.int64, written)] = True
            noted = noted_rows[sel]
            # plain dict lookups below; copied by the views (dict.copy of a LazyNotes goes
            # through its keys(), which would write the pending notes)
            notes = dict(zip(dict.keys(notes), dict.values(notes), strict=True))
        elif pairs is not None:
            notes = {}
        lazy = batch.row_index()  # rows with PDO signals or shared notes
        in_block = shared = None
        if lazy is not None:
            in_block = lazy[0][sel]
            shared = lazy[2][sel]
            noted = noted | (in_block >= 0) | (shared >= 0)
        with_records = np.zeros(n, bool)
        if by_row:
            rec_rows = np.zeros(len(fb), bool)
            rec_rows[[r for r in by_row if 0 <= r < nrows]] = True
            with_records = rec_rows[sel]
        keyed = _KEYED[svc] & ~noted & ~with_records
        inv, first_at = _key_groups(svc, pdo, rtr, dlc, data, keyed)
        texts: list[bytes] = [b""]  # group 0: rows whose text comes from elsewhere
        for i in first_at[1:].tolist():
            f = frame_fields(int(svc[i]), fb.payload(int(sel[i])), bool(rtr[i]))
            texts.append(
                (annotation(int(svc[i]), int(node[i]), int(pdo[i]), f, bool(rtr[i])) + end).encode()
            )
        ann = [(np.arange(n), _padded_table(texts)[inv])]
        done = keyed.copy()
        if in_block is not None:
            free = ~with_records & (in_block >= 0)
            if notes:
                free &= ~noted_rows[sel]
            plans = []
            for k, sb in enumerate(batch.signals):
                plan = _signal_text(batch, k, sb, sel, free & (in_block == k), shared, endb)
                if plan is not None:
                    plans.append(plan)
                    done[plan[0]] = True
            ann += _format_plans(plans)
        emcy = np.flatnonzero(~done & ~noted & ~with_records & (svc == Service.EMCY))
        if emcy.size:
            ann.append(_emcy_text(data[emcy], dlc[emcy], emcy, endb))
            done[emcy] = True
        if pairs is not None:
            self._pair_texts(pairs, fb, endb, ann, done)
        # rows whose own text is in a column already: their record lines spliced in after it
        extra = {i: by_row[int(sel[i])] for i in np.flatnonzero(with_records & done).tolist()}
        # every other row without records: its text from Python, scattered in
        spliced: dict[int, bytes] = {}
        per_row = np.flatnonzero(~done & ~with_records)
        if per_row.size:
            is_sdo = ((svc == Service.SDO_REQUEST) | (svc == Service.SDO_RESPONSE))[
                per_row
            ].tolist()
            chunks = []
            for i, row, sdo in zip(per_row.tolist(), sel[per_row].tolist(), is_sdo, strict=True):
                note = notes.get(row) if sdo else None
                role = note.get("role") if note else None
                if role:  # what `annotation` says for a frame the SDO tracker placed
                    chunks.append("SDO " + role + end)
                else:
                    rtr_i = bool(flags[i] & FLAG_RTR)
                    f = row_fields(batch, row)
                    chunks.append(
                        annotation(int(svc[i]), int(node[i]), int(pdo[i]), f, rtr_i) + end
                    )
            encoded = [c.encode() for c in chunks]
            with_nul = [j for j, c in enumerate(encoded) if b"\0" in c]
            for j in with_nul:  # NULs are the padding: splice these rows in after compaction
                spliced[int(per_row[j])] = encoded[j]
                encoded[j] = b""
            ann.append(_ragged(per_row, encoded))
        width = max(m.shape[1] for _, m in ann)
        ann_col = np.zeros((n, width), np.uint8)
        for rows, m in ann:
            ann_col[rows, : m.shape[1]] = m
        rebuilt = (flags & FLAG_RECONSTRUCTED) != 0
        if rebuilt.any():
            parts.append(_MARK_COL[rebuilt.astype(np.intp)])
        parts.append(ann_col)

        if spliced:
            with_records[list(spliced)] = True
        if extra:
            with_records[list(extra)] = True
        slow = np.flatnonzero(with_records)
        inserts: list[bytes] = []  # what follows each slow row's line
        is_sdo = ((svc == Service.SDO_REQUEST) | (svc == Service.SDO_RESPONSE))[slow].tolist()
        for i, row, sdo in zip(slow.tolist(), sel[slow].tolist(), is_sdo, strict=True):
            if i in spliced:
                inserts.append(spliced[i])
                continue
            if i in extra:
                inserts.append(extra[i])
                continue
            note = notes.get(row) if sdo else None
            role = note.get("role") if note else None
            if role:
                text = "SDO " + role
            else:
                rtr_i = bool(flags[i] & FLAG_RTR)
                text = annotation(
                    int(svc[i]), int(node[i]), int(pdo[i]), row_fields(batch, row), rtr_i
                )
            inserts.append((text + end).encode() + by_row[row])
        tail = ("\n".join(tail_lines) + "\n").encode() if tail_lines else b""
        return Rendered(parts, n, slow, inserts, tail)

    @staticmethod
    def _pair_texts(pairs, fb, endb, ann, done) -> None:
        """The fast pairs' rows: "SDO <role>" into the annotation column (`ann`, marked
        `done`), worded from their columns."""
        fields, fast = pairs
        req, resp = fast.cols.req_row, fast.cols.row
        req_role, resp_role = pair_roles(fb, fields, req, resp, endb)
        ann.append((req, req_role))
        ann.append((resp, resp_role))
        done[req] = True
        done[resp] = True


def _joined_by_row(rows: list[int], lines: list[bytes]) -> dict[int, bytes]:
    """row -> its lines joined, in their order (a batch's records, then its findings): one
    join and one slice per row (a polled bus has a record on a few percent of its rows)."""
    if not lines:
        return {}
    r = np.asarray(rows, np.int64)
    order = np.argsort(r, kind="stable")
    ordered = [lines[k] for k in order.tolist()]
    ends = np.cumsum(np.fromiter(map(len, ordered), np.int64, len(ordered)))
    r = r[order]
    last = np.append(np.flatnonzero(r[1:] != r[:-1]), len(r) - 1)  # each row's last line
    first_end = np.concatenate(([0], ends[last[:-1]]))
    blob = b"".join(ordered)
    return {
        row: blob[a:b]
        for row, a, b in zip(r[last].tolist(), first_end.tolist(), ends[last].tolist(), strict=True)
    }


class Rendered:
    """A batch's lines before the last step: the column blocks, and what goes in after
    some rows (record lines, texts with NULs) and after the last.

    `bytes()` compacts and splices: a C pass without the GIL and a join, which the
    background writer does while the caller renders the next batch. An insert goes
    `back` bytes before its row's end (0: after the row), in the order given.
    """

    def __init__(
        self,
        parts: list[np.ndarray],
        n: int,
        after: np.ndarray,
        inserts: list[bytes],
        tail: bytes,
        back: list[int] | None = None,
    ) -> None:
        self.parts, self.n, self.after, self.inserts, self.tail = parts, n, after, inserts, tail
        self.back = back

    def bytes(self) -> bytes:
        return b"".join(self.pieces())

    def pieces(self) -> list:
        """The finished bytes as pieces to write one after another (views into the
        compacted block between the inserts): joined, a batch's 150 MB of JSONL were
        copied twice more, by the slices and by the join."""
        blob, ends = _compact(self.parts, self.n, with_ends=self.after.size > 0)
        self.parts = []
        if not self.inserts:
            return [blob, self.tail] if self.tail else [blob]
        at = ends[self.after]
        if self.back is not None:
            at = at - np.asarray(self.back, np.int64)
        view = memoryview(blob)
        pieces: list = []
        prev = 0
        for e, insert in zip(at.tolist(), self.inserts, strict=True):
            pieces.append(view[prev:e])
            pieces.append(insert)
            prev = e
        pieces.append(view[prev:])
        pieces.append(self.tail)
        return pieces


def _key_groups(
    svc, pdo, rtr, dlc, data, keyed, byte_matters: np.ndarray = _BYTE_MATTERS
) -> tuple[np.ndarray, np.ndarray]:
    """(group of each row, first row of each group): keyed rows grouped by what their
    text depends on (service, PDO number, RTR, the first byte where it matters, the
    length where that does); group 0 is every other row. Counted over a dense key
    (the (service, PDO, RTR) combinations present, then the byte or length) in O(n):
    np.unique sorted all the rows, three times as long."""
    n = svc.size
    inv = np.zeros(n, np.int64)
    if not keyed.any():
        return inv, np.zeros(1, np.int64)
    is_pdo = (svc == Service.TPDO) | (svc == Service.RPDO)
    combo = (svc.astype(np.int64) * 256 + np.where(is_pdo, pdo, 0)) * 2 + (rtr & is_pdo)
    present = np.bincount(combo[keyed], minlength=1 << 17) > 0
    compact = np.cumsum(present) - 1  # combination -> its number among those present
    first = np.where((dlc > 0) & byte_matters[svc], data[:, 0].astype(np.int64), 256)
    first = np.where(_LENGTH_MATTERS[svc], dlc, first)  # 0..64: below 256
    dense = (compact[combo] * 257 + first)[keyed]
    group_of = np.cumsum(np.bincount(dense) > 0)  # dense key -> group (1, 2, ...), in order
    inv[keyed] = group_of[dense]
    first_at = np.full(int(group_of[-1]) + 1, n, np.int64)
    np.minimum.at(first_at, inv, np.arange(n))
    return inv, first_at


def _ragged(rows: np.ndarray, texts: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    """(rows, NUL-padded matrix) holding one bytes string per row, without a loop."""
    lengths = np.fromiter(map(len, texts), np.int64, len(texts))
    width = int(lengths.max()) if lengths.size else 0
    flat = np.frombuffer(b"".join(texts), np.uint8)
    out = np.zeros((len(texts), width), np.uint8)
    out[np.arange(width)[None, :] < lengths[:, None]] = flat
    return rows, out


def _emcy_text(
    data: np.ndarray, dlc: np.ndarray, at: np.ndarray, endb: bytes
) -> tuple[np.ndarray, np.ndarray]:
    """The annotation of EMCY rows without notes (`protocol.emcy.text_columns`) and the end."""
    parts = [*emcy_text.text_columns(data, dlc), _bytecols.repeat(endb, at.size)]
    return at, np.concatenate([np.broadcast_to(p, (at.size, p.shape[1])) for p in parts], axis=1)


def _signal_text(
    batch: DecodedBatch,
    k: int,
    sb,
    sel: np.ndarray,
    take: np.ndarray,
    shared: np.ndarray,
    endb: bytes,
) -> tuple[np.ndarray, list] | None:
    """The annotation of the printed rows of signal block k, as parts to concatenate.

    Parts are byte matrices, or 1-tuples of a value column still to be formatted
    (`_format_plans`, so that all float columns of a batch are formatted at once).

    `take` marks positions (in the printed rows) whose text is `annotation` of the
    block's values alone, plus at most a shared `pdo_problem`; None when the block
    has no such rows or looks unusual (then the rows go the per-row way).
    """
    at = np.flatnonzero(take)
    if at.size == 0:
        return None
    rows = sel[at]
    fb = batch.frames
    svc = batch.service[rows]
    pdo = batch.pdo[rows]
    if (svc != svc[0]).any() or (pdo != pdo[0]).any() or (fb.flags[rows] & FLAG_RTR).any():
        return None
    if sb.choices:
        return None  # value-table names: the per-row way
    pos = batch.row_index()[1][rows]
    parts: list[np.ndarray] = []
    m = rows.size

    def const(text: str) -> None:
        b = text.encode()
        if b:
            parts.append(np.broadcast_to(np.frombuffer(b, np.uint8), (m, len(b))))

    units = {name: u for name, u in sb.units.items() if u}
    if any("\0" in x for x in (*sb.columns, *units.values())):
        return None  # NULs are the padding: such text goes the per-row way
    if int(svc[0]) in (Service.TPDO, Service.RPDO):
        lead = f"{'TPDO' if int(svc[0]) == Service.TPDO else 'RPDO'}{int(pdo[0])}  "
    elif int(svc[0]) == Service.SRDO:
        lead = f"SRDO{int(pdo[0])} normal  "
    else:
        lead = f"{sb.pdo}  "  # a DBC message on an identifier CANopen does not use
    for j, (name, col) in enumerate(sb.columns.items()):
        const((lead if j == 0 else " ") + f"{name}=")
        parts.append((col[pos],))  # formatted with every block's columns at once
        if units.get(name):
            const(f" {units[name]}")
        if name in sb.words:  # a statusword's state, a mode's name: one text per value
            texts, inv = word_column(sb.words[name], col[pos])
            parts.append(_padded_table([f" ({w})".encode() if w else b"" for w in texts])[inv])
    if not sb.columns:
        return None
    # shared notes: only a pdo_problem is known to print as a plain suffix
    sh = shared[at]
    problems = np.zeros(m, np.intp)
    table = [b""]
    for s in np.unique(sh[sh >= 0]).tolist():
        note = batch.row_notes[s][1]
        if set(note) != {"pdo_problem"}:
            return None
        text = f"  [{note['pdo_problem']}]" if note["pdo_problem"] else ""
        if "\0" in text:
            return None
        table.append(text.encode())
        problems[sh == s] = len(table) - 1
    if len(table) > 1:
        parts.append(_padded_table(table)[problems])
    const(endb.decode())
    return at, parts


def _format_plans(plans: list) -> list[tuple[np.ndarray, np.ndarray]]:
    """Fill in the value columns of `_signal_text` plans: all float columns in one call."""
    floats = [
        p[0] for _, parts in plans for p in parts if type(p) is tuple and p[0].dtype.kind == "f"
    ]
    texts = iter(())
    if floats:
        sizes = np.cumsum([f.size for f in floats])[:-1]
        texts = iter(np.split(g6_text(np.concatenate(floats)), sizes))
    out = []
    for at, parts in plans:
        filled = []
        for p in parts:
            if type(p) is tuple:
                filled.append(next(texts) if p[0].dtype.kind == "f" else value_text(p[0]))
            else:
                filled.append(p)
        out.append((at, np.concatenate(filled, axis=1)))
    return out


def lines_per_row(
    batch: DecodedBatch, mask: np.ndarray | None, t0: float, color: bool, only_records: bool
) -> list[str]:
    """The output lines of a batch, built row by row (odd batches; the fast writer's reference)."""
    fb = batch.frames
    by_row: dict[int, list[dict]] = {}
    records = batch.records_and_findings()
    for row, rec in records:
        by_row.setdefault(row, []).append(rec)
    rows = range(len(fb)) if mask is None else np.flatnonzero(mask).tolist()
    lines: list[str] = []
    if not only_records:
        rel = (fb.t - t0).tolist()
        ids = fb.can_id.tolist()
        flags = fb.flags.tolist()
        dlcs = fb.dlc.tolist()
        nodes = batch.node.tolist()
        pdos = batch.pdo.tolist()
        services = batch.service.tolist()
        for i in rows:
            fl = flags[i]
            ident = f"{ids[i]:08X}" if fl & (FLAG_EXT | FLAG_ERR) else f"{ids[i]:03X}"
            if fl & FLAG_RTR:
                data = "remote request"
            else:
                data = "".join(_HEX3[b] for b in fb.payload(i)).rstrip()
            svc = SERVICE_NAMES[services[i]]
            node = nodes[i]
            text = annotation(services[i], node, pdos[i], row_fields(batch, i), bool(fl & FLAG_RTR))
            if fl & FLAG_RECONSTRUCTED:
                text = _MARK + text
            ch = fb.channel_name(i)
            line = (
                f"{rel[i]:12.6f}  {ch:<5} {ident:>8}  [{dlcs[i]}]  {data:<23}  "
                f"{svc:<14} {'' if node < 0 else node:>3}  {text}"
            )
            if color:
                line = f"{_COLOURS.get(svc, '')}{line}{_RESET}"
            lines.append(line)
            for rec in by_row.get(i, ()):
                lines.append("    └─ " + format_record(rec))
    # records of rows not printed (filtered out, records-only view, end of log) still print;
    # alone (--sdo) each carries its time as a frame line does
    shown = set() if only_records else (set(rows) if mask is not None else set(range(len(fb))))
    for row, rec in records:
        if row not in shown:
            text = format_record(rec) if only_records else format_alone(rec, t0)
            t = rec.get("t")
            if only_records and isinstance(t, (int, float)):
                text = f"{t - t0:12.6f}  {text}"
            lines.append(text)
    return lines
