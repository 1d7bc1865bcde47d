"""SdoRecords: every SDO transfer one batch completed, the one type every reader reads.

A transfer is made in one of two places: the tracker (any protocol, one frame at
a time) or its columnar fast path (an expedited request and its answer, most of
a polled bus). Both land here, in the order they ended. Readers start from the
columns every transfer has (`cols`: row, node, index, upload, ok, latency...)
to pick the few they need, then read those as dicts (`record`). The fast path's
dicts are built only when read: `decode --summary` and `check` never build them.
Outputs that write every transfer take the fast part whole (`split`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from cananalyze.core.columns.order import first_seen_codes

# The columns of the `sdo` table (Capture.sdo, sdo.parquet), in order: the record's
# keys less `kind` and the tracker's extras (frames, cob_ids).
SDO_TABLE_COLUMNS = (
    "t_start",
    "t",
    "latency_ms",
    "node",
    "direction",
    "protocol",
    "index",
    "subindex",
    "size",
    "data",
    "value",
    "name",
    "result",
    "abort_code",
    "abort_text",
    "detail",
    "words",
)
RECORD_COLUMNS = SDO_TABLE_COLUMNS

# the fields every ok expedited pair has alike, and the arrays that hold the others
OK_CONSTANTS = {
    "protocol": "expedited",
    "result": "ok",
    "abort_code": None,
    "abort_text": None,
    "detail": None,
}
NUMBER_FIELDS = ("t_start", "t", "latency_ms", "node", "index", "subindex", "size")
OBJECT_FIELDS = ("value", "name", "words")
_FLOATS = ("t_start", "t", "latency_ms")
HEX2 = np.array([f"{i:02x}" for i in range(256)], "S2")  # byte -> its hex text


def hex_texts(raw: np.ndarray, length: np.ndarray) -> list[str]:
    """The hex text of each row's first `length` bytes (0..4), as a list, column-wise.

    Byte pairs past the length are emptied, so each row's 8 bytes read as one
    text whose trailing NULs numpy drops.
    """
    m = len(raw)
    pairs = HEX2[raw]  # (m, 4) of 2-character byte texts
    pairs[np.arange(raw.shape[1]) >= np.asarray(length)[:, None]] = b""
    return pairs.view(f"S{2 * raw.shape[1]}").reshape(m).astype(f"U{2 * raw.shape[1]}").tolist()


@dataclass
class RecordColumns:
    """Every SDO transfer of a batch as columns: the one record type every output reads.

    An ok expedited pair (most transfers of a polled bus) is columns only: `arrays`
    holds NUMBER_FIELDS (float64 times and latency, int64 others), `upload` (bool:
    the direction), OBJECT_FIELDS (object arrays), `raw` and `data_len` (the data
    bytes and how many are used, for the hex `data`), `name_code` into `name_labels`
    and, when every decoded value is an int, `value_int` and `value_none` (where
    `value` is None); its other fields are `OK_CONSTANTS`. A transfer the columns do
    not express (an aborted pair; any the tracker made: segmented, block, timed out)
    is `held` as its record dict (position -> record), which wins over the arrays at
    its position. Every output reads these columns and words the held ones by the
    record, so there is one route from the decoder to each output.
    """

    arrays: dict[str, np.ndarray]
    held: dict[int, dict]  # position -> record
    name_labels: list  # the distinct names (or None): `name` is name_labels[name_code]

    def __len__(self) -> int:
        return len(self.arrays["t"])

    @classmethod
    def empty(cls) -> RecordColumns:
        floats = {c: np.zeros(0, np.float64) for c in _FLOATS}
        ints = {c: np.zeros(0, np.int64) for c in NUMBER_FIELDS if c not in floats}
        objects = {c: np.empty(0, object) for c in OBJECT_FIELDS}
        extra = {
            "upload": np.zeros(0, bool),
            "raw": np.zeros((0, 4), np.uint8),
            "data_len": np.zeros(0, np.int64),
            "name_code": np.zeros(0, np.int64),
            "value_int": np.zeros(0, np.int64),
            "value_none": np.zeros(0, bool),
        }
        return cls(floats | ints | objects | extra, {}, [None])

    @classmethod
    def of_records(cls, recs: list[dict]) -> RecordColumns:
        """Record dicts (the tracker's: a few per batch) as held rows; the arrays carry
        what readers that go by column alone take (times, node, object, direction)."""
        m = len(recs)
        if m == 0:
            return cls.empty()

        def floats(key: str, none: float) -> np.ndarray:
            vals = [r.get(key) for r in recs]
            return np.array([none if not isinstance(v, int | float) else v for v in vals], float)

        def objects(key: str) -> np.ndarray:
            out = np.empty(m, object)
            out[:] = [r.get(key) for r in recs]
            return out

        arrays = {
            "t_start": floats("t_start", np.nan),
            "t": floats("t", 0.0),
            "latency_ms": floats("latency_ms", np.nan),
            **{c: np.array([_int(r.get(c)) for r in recs], np.int64) for c in NUMBER_FIELDS[3:]},
            "upload": np.array([r.get("direction") == "upload" for r in recs], bool),
            **{c: objects(c) for c in OBJECT_FIELDS},
            "raw": np.zeros((m, 4), np.uint8),
            "data_len": np.zeros(m, np.int64),
            "name_code": np.zeros(m, np.int64),
            "value_int": np.zeros(m, np.int64),
            "value_none": np.ones(m, bool),
        }
        return cls(arrays, dict(enumerate(recs)), [None])

    @classmethod
    def concat(cls, parts: list[RecordColumns]) -> RecordColumns:
        parts = [p for p in parts if len(p)]
        if len(parts) <= 1:
            return parts[0] if parts else cls.empty()
        keys = set.intersection(*(set(p.arrays) for p in parts))  # value_int: all or none
        labels: list = []
        held: dict[int, dict] = {}
        codes, start = [], 0
        for p in parts:
            codes.append(p.arrays["name_code"] + len(labels))
            labels += p.name_labels
            held.update((start + k, rec) for k, rec in p.held.items())
            start += len(p)
        arrays = {k: np.concatenate([p.arrays[k] for p in parts]) for k in keys}
        arrays["name_code"] = np.concatenate(codes)
        return cls(arrays, held, labels)

    def take(self, at: np.ndarray) -> RecordColumns:
        """The transfers at positions `at` (each once), in that order."""
        at = np.asarray(at, np.int64)
        new = np.full(len(self), -1, np.int64)
        new[at] = np.arange(at.size)
        held = {int(new[k]): rec for k, rec in self.held.items() if new[k] >= 0}
        return RecordColumns({k: v[at] for k, v in self.arrays.items()}, held, self.name_labels)

    @cached_property
    def columns(self) -> dict[str, list]:
        """One list per RECORD_COLUMNS key, values as in the records."""
        a = self.arrays
        m = len(self)
        columns: dict[str, list] = {c: a[c].tolist() for c in NUMBER_FIELDS + OBJECT_FIELDS}
        columns["data"] = hex_texts(a["raw"], a["data_len"])
        columns["direction"] = np.where(a["upload"], "upload", "download").tolist()
        for c, v in OK_CONSTANTS.items():
            columns[c] = [v] * m
        for k, rec in self.held.items():
            for c in RECORD_COLUMNS:
                columns[c][k] = rec.get(c)
        return {c: columns[c] for c in RECORD_COLUMNS}

    def record(self, j: int) -> dict:
        """The j-th record as `records()` makes it, key for key, read from the arrays: a
        reader of a few records (the OD tally's last transfer of each object) does not
        build every record's lists for them."""
        if j in self.held:
            return self.held[j]
        a = self.arrays
        nd = int(a["node"][j])
        return {
            "kind": "sdo",
            "t_start": a["t_start"][j].item(),
            "t": a["t"][j].item(),
            "latency_ms": a["latency_ms"][j].item(),
            "node": nd,
            "direction": "upload" if a["upload"][j] else "download",
            "protocol": "expedited",
            "index": a["index"][j].item(),
            "subindex": a["subindex"][j].item(),
            "size": a["size"][j].item(),
            "data": a["raw"][j, : a["data_len"][j]].tobytes().hex(),
            "value": a["value"][j],
            "name": a["name"][j],
            "result": "ok",
            "abort_code": None,
            "abort_text": None,
            "detail": None,
            "words": a["words"][j],
            "frames": 2,
            "cob_ids": [0x600 + nd, 0x580 + nd],
        }

    def records(self) -> list[dict]:
        c = self.columns
        out = [
            {
                "kind": "sdo",
                "t_start": x,
                "t": y,
                "latency_ms": lat,
                "node": nd,
                "direction": dr,
                "protocol": "expedited",
                "index": i,
                "subindex": s,
                "size": n,
                "data": h,
                "value": v,
                "name": nm,
                "result": "ok",
                "abort_code": None,
                "abort_text": None,
                "detail": None,
                "words": w,
                "frames": 2,
                "cob_ids": [0x600 + nd, 0x580 + nd],
            }
            for x, y, lat, nd, dr, i, s, n, h, v, nm, w in zip(
                c["t_start"],
                c["t"],
                c["latency_ms"],
                c["node"],
                c["direction"],
                c["index"],
                c["subindex"],
                c["size"],
                c["data"],
                c["value"],
                c["name"],
                c["words"],
                strict=True,
            )
        ]
        for k, rec in self.held.items():
            out[k] = rec
        return out


@dataclass
class SdoColumns:
    """What every reader's first pass needs of a run of transfers, as columns."""

    row: np.ndarray  # int64 row the record is attached to (the answer; n: after the batch)
    req_row: np.ndarray  # int64 row of a fast pair's request, else -1
    node: np.ndarray  # int64, -1 where the record has none
    upload: np.ndarray  # bool (else download or unknown)
    index: np.ndarray  # int64, -1 where none
    subindex: np.ndarray  # int64, -1 where none
    ok: np.ndarray  # bool: result "ok"
    latency: np.ndarray  # float64 latency_ms, NaN where none
    t: np.ndarray  # float64 end time

    FIELDS = ("row", "req_row", "node", "upload", "index", "subindex", "ok", "latency", "t")

    def __len__(self) -> int:
        return len(self.row)

    def take(self, at: np.ndarray) -> SdoColumns:
        return SdoColumns(*(getattr(self, f)[at] for f in self.FIELDS))

    @classmethod
    def concat(cls, parts: list[SdoColumns]) -> SdoColumns:
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in cls.FIELDS))

    @classmethod
    def of_records(cls, rows: list[int], recs: list[dict]) -> SdoColumns:
        """Columns of record dicts (the tracker's: a few per batch)."""

        def ints(key: str) -> np.ndarray:
            return np.array([_int(r.get(key)) for r in recs], np.int64)

        lat = [r.get("latency_ms") for r in recs]
        return cls(
            row=np.asarray(rows, np.int64),
            req_row=np.full(len(recs), -1, np.int64),
            node=ints("node"),
            upload=np.array([r.get("direction") == "upload" for r in recs], bool),
            index=ints("index"),
            subindex=ints("subindex"),
            ok=np.array([r.get("result") == "ok" for r in recs], bool),
            latency=np.array([np.nan if v is None else v for v in lat], np.float64),
            t=np.array([r.get("t") or 0.0 for r in recs], np.float64),
        )


def _int(v) -> int:
    """An int field as a column holds it; -1 for none (or none that fits)."""
    return v if type(v) is int and -(1 << 63) <= v < 1 << 63 else -1


@dataclass
class SdoTable:
    """Every transfer's node and result as codes into small key lists, in record order."""

    node_keys: list
    node: np.ndarray  # int64 code into node_keys
    result_keys: list
    result: np.ndarray  # int64 code into result_keys
    latency: np.ndarray  # float64 ms, NaN where the record has none
    slots: np.ndarray  # int64 position of each in the SdoRecords

    def first_seen(self, codes: np.ndarray) -> list[int]:
        """Distinct codes in the order they first appear (dict insertion order of a loop)."""
        if codes is self.node or codes is self.result:  # numbered in that order already
            return list(range(len(self.node_keys if codes is self.node else self.result_keys)))
        return _int_codes(codes)[0]

    def groups(self, codes: np.ndarray, where: np.ndarray | None = None) -> list:
        """(code, positions in record order) per distinct code, first seen first.

        One stable sort instead of a mask per code; `where` picks the records taken.
        """
        sel = np.arange(codes.size) if where is None else np.flatnonzero(where)
        if sel.size == 0:
            return []
        c = codes[sel]
        small = c.dtype.kind in "iu" and int(c.min()) >= 0 and int(c.max()) <= 0xFFFF
        # (codes that fit 16 bits: numpy's stable sort of uint16 is a radix sort)
        order = np.argsort(c.astype(np.uint16) if small else c, kind="stable")
        cs = c[order]
        cut = np.flatnonzero(cs[1:] != cs[:-1]) + 1
        starts = np.concatenate(([0], cut))
        ends = np.concatenate((cut, [cs.size]))
        pos = sel[order]
        out = [
            (code, pos[a:b])
            for code, a, b in zip(cs[starts].tolist(), starts.tolist(), ends.tolist(), strict=True)
        ]
        out.sort(key=lambda g: g[1][0])  # first seen first
        return out


@dataclass
class FastPart:
    """A run of fast-path transfers: their first-pass columns, and the rest when asked.

    `fields()` builds every field of all of them (`RecordColumns`), `build(js)` the
    dicts of a few (js: positions in this part) for readers that pick one or two.
    """

    at: np.ndarray  # int64 position of each in the SdoRecords, ascending
    cols: SdoColumns
    build: Callable[[np.ndarray], list[dict]]
    fields: Callable[[], RecordColumns]


class SdoRecords:
    """The batch's SDO transfers in the order they ended: (row, record) by position."""

    def __init__(self, pairs=()) -> None:
        self._rows: list[int] = []  # row of each position (fast ones: filled on seal)
        self._dicts: dict[int, dict] = {}  # position -> record, as appended
        self._built: dict[int, dict] = {}  # position -> fast record, built when read
        self._fast: list[FastPart] = []
        self._cols: SdoColumns | None = None
        self._table: SdoTable | None = None
        self._fields: RecordColumns | None = None
        for row, rec in pairs:
            self.append(row, rec)

    # --- building (the SDO processor, merges) ---------------------------------------
    def append(self, row: int, record: dict) -> None:
        self._dicts[len(self._rows)] = record
        self._rows.append(row)
        self._cols = self._table = self._fields = None

    def reserve(self, k: int) -> int:
        """k positions for fast transfers still to come (`defer`); returns the first."""
        first = len(self._rows)
        self._rows.extend([-1] * k)
        self._cols = self._table = self._fields = None
        return first

    def defer(self, part: FastPart) -> None:
        """The reserved positions `part.at` are `part`'s transfers."""
        at, rows = part.at, part.cols.row.tolist()
        if len(rows) == at.size and at.size and int(at[-1]) - int(at[0]) + 1 == at.size:  # one run
            self._rows[int(at[0]) : int(at[-1]) + 1] = rows
        else:
            for k, r in zip(at.tolist(), rows, strict=True):
                self._rows[k] = r
        self._fast.append(part)
        self._cols = self._table = self._fields = None

    # --- reading -------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._rows)

    def __bool__(self) -> bool:
        return bool(self._rows)

    @property
    def rows(self) -> list[int]:
        return self._rows

    @property
    def cols(self) -> SdoColumns:
        """Every transfer's columns, by position; built once (the tracker's from dicts)."""
        if self._cols is None:
            d = sorted(self._dicts)
            parts = [SdoColumns.of_records([self._rows[k] for k in d], [self._dicts[k] for k in d])]
            at = [np.asarray(d, np.int64)]
            for p in self._fast:
                parts.append(p.cols)
                at.append(p.at)
            if not d and len(self._fast) == 1:  # the usual batch: one fast part, in order
                parts, at = parts[1:], at[1:]
            pos = np.concatenate(at)
            if len(parts) == 1:  # (a new SdoColumns of the same arrays: none is written to)
                cols = SdoColumns(*(getattr(parts[0], f) for f in SdoColumns.FIELDS))
            else:
                cols = SdoColumns.concat(parts)
            if self._fast and (pos[1:] < pos[:-1]).any():
                cols = cols.take(np.argsort(pos, kind="stable"))
            self._cols = cols
        return self._cols

    def record(self, k: int) -> dict:
        """The record at position k (a fast one built now, and kept)."""
        rec = self._dicts.get(k)
        if rec is None:
            rec = self._built.get(k)
        if rec is None and self._fields is not None and 0 <= k < len(self._fields):
            # the part's fields are columns already (an export's tables): read this
            # transfer from their arrays, not through a build of it
            rec = self._built[k] = self._fields.record(k)
        if rec is None:
            for p in self._fast:
                j = int(np.searchsorted(p.at, k))
                if j < p.at.size and p.at[j] == k:
                    rec = self._built[k] = p.build(np.array([j]))[0]
                    break
            else:
                raise IndexError(k)
        return rec

    def picked(self, at) -> list[tuple[int, dict]]:
        """(row, record) of these positions, in the order given."""
        return [(self._rows[k], self.record(k)) for k in at]

    def _realise(self) -> None:
        """Every fast transfer's dict written in (one build per part)."""
        for p in self._fast:
            todo = [j for j, k in enumerate(p.at.tolist()) if k not in self._built]
            if not todo:
                continue
            built = p.build(None) if len(todo) == p.at.size else p.build(np.array(todo))
            js = range(p.at.size) if len(todo) == p.at.size else todo
            at = p.at.tolist()
            for j, rec in zip(js, built, strict=True):
                self._built[at[j]] = rec

    def __iter__(self) -> Iterator[tuple[int, dict]]:
        self._realise()
        d = self._dicts | self._built
        return iter([(row, d[k]) for k, row in enumerate(self._rows)])

    def __getitem__(self, k: int) -> tuple[int, dict]:
        if k < 0:
            k += len(self._rows)
        return self._rows[k], self.record(k)

    def __eq__(self, other) -> bool:
        if isinstance(other, SdoRecords | list):
            return list(self) == list(other)
        return NotImplemented

    def __repr__(self) -> str:
        return f"SdoRecords({len(self)} transfers, {sum(p.at.size for p in self._fast)} fast)"

    def __reduce__(self):
        return (SdoRecords, (list(self),))

    def fast_part(self) -> FastPart | None:
        """The fast path's pairs when they are one part (a batch of one bus as the
        processor made it): the text outputs word their frames' roles from its columns."""
        return self._fast[0] if len(self._fast) == 1 else None

    def fields(self) -> RecordColumns:
        """Every transfer's fields as columns, by position: what every output reads.

        Built once, when first asked (`decode --summary` and `check` never ask): the
        fast parts' columns, and the tracker's records held as they are.
        """
        if self._fields is None:
            d = sorted(self._dicts)
            parts = [RecordColumns.of_records([self._dicts[k] for k in d])]
            at = [np.asarray(d, np.int64)]
            for p in self._fast:
                parts.append(p.fields())
                at.append(p.at)
            fields = RecordColumns.concat(parts)
            pos = np.concatenate(at)
            if (pos[1:] < pos[:-1]).any():
                fields = fields.take(np.argsort(pos, kind="stable"))
            self._fields = fields
        return self._fields

    def table(self) -> SdoTable:
        """Node and result codes of every transfer (summary, timing, the report read it)."""
        if self._table is None:
            c = self.cols
            d = self._dicts
            nodes = c.node
            odd = [k for k, rec in d.items() if c.node[k] < 0 and rec.get("node") is not None]
            if odd:  # a node that is no int (hand-made records): coded by value
                node, node_keys = first_seen_codes(
                    [d[k]["node"] if k in d else v for k, v in enumerate(nodes.tolist())]
                )
            else:
                node_keys, node = _int_codes(nodes)
                node_keys = [None if v < 0 else v for v in node_keys]
            raw = np.where(c.ok, 0, 1)  # the fast path's: ok or abort
            labels = ["ok", "abort"]
            for k, rec in d.items():
                r = rec.get("result")
                if r not in labels:
                    labels.append(r)
                raw[k] = labels.index(r)
            keys, result = _int_codes(raw)
            result_keys = [labels[v] for v in keys]
            self._table = SdoTable(
                node_keys, node, result_keys, result, c.latency, np.arange(len(c), dtype=np.int64)
            )
        return self._table

    # --- reshaping -------------------------------------------------------------------
    def take(self, at: list[int], rows: list[int]) -> SdoRecords:
        """The transfers at positions `at` (written), attached to `rows`."""
        return SdoRecords(zip(rows, (self.record(k) for k in at), strict=True))

    @staticmethod
    def merge(parts: list[tuple[np.ndarray, SdoRecords]]) -> tuple[SdoRecords, np.ndarray]:
        """Several parts' transfers at the batch's rows ((row map, records) each), in row
        order (stable), and the part each came from. Fast transfers stay unbuilt."""
        rows, of = [], []
        for p, (at, recs) in enumerate(parts):
            r = np.asarray(recs.rows, np.int64)
            rows.append(at[np.clip(r, 0, at.size - 1)])
            of.append(np.full(len(recs), p, np.int64))
        out = SdoRecords()
        if not rows:
            return out, np.zeros(0, np.int64)
        row = np.concatenate(rows)
        part = np.concatenate(of)
        order = np.argsort(row, kind="stable")
        where = np.empty(order.size, np.int64)  # merged position of each (part, position)
        where[order] = np.arange(order.size)
        start = np.cumsum([0] + [len(r) for _, r in parts])
        out._rows = row[order].tolist()
        for p, (at, recs) in enumerate(parts):
            for j, rec in recs._dicts.items():
                out._dicts[int(where[start[p] + j])] = rec
            for j, rec in recs._built.items():
                out._built[int(where[start[p] + j])] = rec
            for fp in recs._fast:
                mapped = where[start[p] + fp.at]
                o = np.argsort(mapped, kind="stable")  # (a timeout's row may come earlier)
                cols = fp.cols.take(o)
                cols.row = at[np.clip(cols.row, 0, at.size - 1)]
                cols.req_row = np.where(
                    cols.req_row >= 0, at[np.clip(cols.req_row, 0, at.size - 1)], -1
                )
                out._fast.append(
                    FastPart(mapped[o], cols, _reordered(fp.build, o), _taken(fp.fields, o))
                )
        return out, part[order]


def _int_codes(values: np.ndarray) -> tuple[list, np.ndarray]:
    """(distinct values first seen first, each value's code) of an int array, column-wise
    (`first_seen_codes`'s, the other way round)."""
    if values.size == 0:
        return [], np.zeros(0, np.int64)
    lo, hi = (int(values.min()), int(values.max())) if values.dtype.kind in "iu" else (-2, 0)
    if lo >= -1 and hi < 0xFFFF:
        # small values (nodes, result codes): counted, and sorted by a radix sort of
        # uint16 (stable: each value's first position is its run's first)
        small = values.astype(np.uint16) + np.uint16(1)  # (-1 wraps to 0xFFFF, then 0)
        counts = np.bincount(small)
        present = np.flatnonzero(counts)
        if present.size == 1:
            return [lo], np.zeros(values.size, np.int64)
        order = np.argsort(small, kind="stable")
        starts = np.concatenate(([0], np.cumsum(counts[present])[:-1]))
        by_first = np.argsort(order[starts])
        code_of = np.zeros(counts.size, np.int64)
        code_of[present[by_first]] = np.arange(present.size)
        return (present[by_first] - 1).tolist(), code_of[small]
    uniq, first, inv = np.unique(values, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty(order.size, np.int64)
    rank[order] = np.arange(order.size)
    return uniq[order].tolist(), rank[inv.reshape(-1)]


def _reordered(build: Callable, o: np.ndarray) -> Callable:
    """`build` of a part whose transfers were put in the order `o`."""

    def reordered(js: np.ndarray | None) -> list[dict]:
        return build(o if js is None else o[js])

    return reordered


def _taken(fields: Callable[[], RecordColumns], o: np.ndarray) -> Callable[[], RecordColumns]:
    """`fields` of a part whose transfers were put in the order `o`."""
    return lambda: fields().take(o)
