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

import numpy as np

from cananalyze.core.columns.order import first_seen_codes


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
        if codes.size == 0:
            return []
        uniq, first = np.unique(codes, return_index=True)
        return uniq[np.argsort(first)].tolist()

    def groups(self, codes: np.ndarray, where: np.ndarray | None = None) -> list:
        """(code, positions in record order) per distinct code, first seen first.

        One stable sort instead of a mask per code; `where` picks the records taken.
        """
        sel = np.arange(codes.size) if where is None else np.flatnonzero(where)
        if sel.size == 0:
            return []
        c = codes[sel]
        order = np.argsort(c, kind="stable")
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
    """A run of fast-path transfers: their columns, and their dicts built when asked.

    `build(js)` builds the dicts of some (js: positions in this part), `fields()` all
    of them as columns (`RecordColumns`, which the columnar writers read).
    """

    at: np.ndarray  # int64 position of each in the SdoRecords, ascending
    cols: SdoColumns
    build: Callable[[np.ndarray], list[dict]]
    fields: Callable[[], object] | None = None


class SdoRecords:
    """The batch's SDO transfers in the order they ended: (row, record) by position."""

    def __init__(self, pairs=()) -> None:
        self._rows: list[int] = []  # row of each position (fast ones: filled on seal)
        self._dicts: dict[int, dict] = {}  # position -> record, as appended
        self._built: dict[int, dict] = {}  # position -> fast record, built when read
        self._fast: list[FastPart] = []
        self._cols: SdoColumns | None = None
        self._table: SdoTable | None = None
        for row, rec in pairs:
            self.append(row, rec)

    # --- building (the SDO processor, merges) ---------------------------------------
    def append(self, row: int, record: dict) -> None:
        self._dicts[len(self._rows)] = record
        self._rows.append(row)
        self._cols = self._table = None

    def reserve(self, k: int) -> int:
        """k positions for fast transfers still to come (`defer`); returns the first."""
        first = len(self._rows)
        self._rows.extend([-1] * k)
        self._cols = self._table = None
        return first

    def defer(self, part: FastPart) -> None:
        """The reserved positions `part.at` are `part`'s transfers."""
        for k, r in zip(part.at.tolist(), part.cols.row.tolist(), strict=True):
            self._rows[k] = r
        self._fast.append(part)
        self._cols = self._table = None

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
            pos = np.concatenate(at)
            cols = SdoColumns.concat(parts)
            if self._fast:
                cols = cols.take(np.argsort(pos, kind="stable"))
            self._cols = cols
        return self._cols

    def record(self, k: int) -> dict:
        """The record at position k (a fast one built now, and kept)."""
        rec = self._dicts.get(k)
        if rec is None:
            rec = self._built.get(k)
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

    def split(self) -> tuple[FastPart | None, list[int]]:
        """(the fast transfers, the other positions) when the fast ones are one part with
        its columns (a batch of one bus as the processor made it): the columnar writers
        take that part whole and read the others one by one. Else (None, every position)."""
        part = self._fast[0] if len(self._fast) == 1 else None
        if part is None or part.fields is None:
            return None, list(range(len(self._rows)))
        rest = np.ones(len(self._rows), bool)
        rest[part.at] = False
        return part, np.flatnonzero(rest).tolist()

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
                out._fast.append(FastPart(mapped[o], cols, _reordered(fp.build, o)))
        return out, part[order]


def _int_codes(values: np.ndarray) -> tuple[list, np.ndarray]:
    """(distinct values first seen first, each value's code) of an int array, column-wise
    (`first_seen_codes`'s, the other way round)."""
    if values.size == 0:
        return [], np.zeros(0, np.int64)
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
