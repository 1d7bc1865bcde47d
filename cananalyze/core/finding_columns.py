"""A batch's findings as columns, the way frames, SDO records and signals travel.

A rule that finds one violation per frame (a SYNC counter that jumps on every SYNC, a
heartbeat learned from a jittery log) can find a hundred thousand in a log; a `Finding`
object, its record dict and its event row each cost microseconds apiece. So findings
travel as numpy and object columns (`FindingColumns`), their messages built only when
read (`messages()`: the findings table, the event log; the terminal builds only the
rows it shows), and `Finding` objects are made only where a person reads them (the
terminal's capped list, Python callers iterating); JUnit and JSON at exit read the
columns a chunk of rows at a time.

A finding emitted one at a time (`Rule.emit`: rare, stateful rules) keeps its `Finding`
object in `obj`: live, the heartbeat rule completes the finding of a silence when it
ends, and every output at exit sees the completed one, as before.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

import numpy as np

from cananalyze.core.finding import TABLE_COLUMNS, Finding, tidy

NONE = -1  # node, cob_id, line: none
# columns kept as numpy numbers (the others are object columns)
_INTS = ("node", "cob_id", "line", "row")
_OBJS = ("rule", "severity", "measured", "expected", "why", "basis", "bus")
# the messages of some of a block's rows: a list, or a str object array (no list made)
Texts = Callable[[np.ndarray], "list[str] | np.ndarray"]


def objects(values, n: int) -> np.ndarray:
    """An object column of n values: one per row (a numpy array or a list; a row's
    value may itself be a list, a measured range), or any other value repeated."""
    out = np.empty(n, object)
    if isinstance(values, np.ndarray):
        if values.dtype == object and values.shape == (n,):
            return values.copy()  # as tolist() would give: the same objects
        values = values.tolist()
    if isinstance(values, list):
        return np.fromiter(values, object, n)
    out.fill(values)
    return out


def round6(x: np.ndarray) -> list:
    """`round(v, 6)` of each value (None for NaN), as columns."""
    values = rounded6(x).tolist()
    for i in np.flatnonzero(np.isnan(x)).tolist():
        values[i] = None
    return values


def rounded6(x: np.ndarray) -> np.ndarray:
    """`round(v, 6)` of each value as float64 (NaN stays NaN): numpy's rint(x * 1e6) / 1e6
    is Python's correctly rounded result except where x * 1e6 is within rounding error
    of a half; those few are rounded by Python."""
    r = x * 1e6
    out = np.rint(r) / 1e6
    near = np.abs(np.abs(r - np.floor(r)) - 0.5) < 1e-6 * np.maximum(1.0, np.abs(r) * 1e-9)
    near |= np.abs(r) > 2.0**52  # beyond exact integers: Python decides
    near &= ~np.isnan(x)
    for i in np.flatnonzero(near).tolist():
        out[i] = round(float(x[i]), 6)
    return out


class FindingColumns:
    """Findings as columns: t, t_rel (NaN: none), rule, severity, node/cob_id/line (-1:
    none), message (built lazily), measured, expected, why, basis, row, at_end, bus
    (None: a log of one bus).

    Iterating gives `Finding` objects (built on demand); `records()` the JSON records.
    """

    __slots__ = ("t", "t_rel", "node", "cob_id", "line", "row", "at_end", "_message")
    __slots__ += ("rule", "severity", "measured", "expected", "why", "basis", "bus", "obj")
    __slots__ += ("_texts", "_block", "_local")

    def __init__(self, n: int = 0) -> None:
        self.t = np.zeros(n, np.float64)
        self.t_rel = np.full(n, np.nan)
        for name in _INTS:
            setattr(self, name, np.full(n, NONE, np.int64))
        self.row[:] = 0
        self.at_end = np.zeros(n, bool)
        for name in _OBJS:
            setattr(self, name, np.empty(n, object))
        self.obj = np.empty(n, object)  # the Finding of a row emitted alone, else None
        self._message = np.empty(n, object)  # None until built
        self._texts: list[Texts] = []  # builders, per block
        self._block = np.full(n, NONE, np.int64)  # each row's builder (-1: message built)
        self._local = np.zeros(n, np.int64)  # the row's position in its builder's block

    def __len__(self) -> int:
        return int(self.t.size)

    def __bool__(self) -> bool:
        return self.t.size > 0

    def __repr__(self) -> str:
        return f"FindingColumns({len(self)} findings)"

    # --- building -------------------------------------------------------------
    @classmethod
    def block(
        cls,
        rule: str,
        severity: str | list[str],
        t: np.ndarray,
        node: int | None | np.ndarray,
        cob_id: int | None | np.ndarray,
        text: Texts | Sequence[str],
        measured,
        expected,
        why: str | list[str],
        row=0,
        basis="",
    ) -> FindingColumns:
        """Findings of one rule; `text(idx)` builds the messages of rows `idx` when they
        are read (or a list, built already). Node, COB-ID, severity, why, basis,
        measured and expected: one value for all, or one per row."""
        n = int(np.size(t))
        out = cls(n)
        out.t[:] = t
        out.node[:] = NONE if node is None else node
        out.cob_id[:] = NONE if cob_id is None else cob_id
        out.row[:] = row
        out.rule.fill(rule)
        out.severity = objects(severity, n)
        out.why = objects(why, n)
        out.basis = objects(basis, n)
        out.measured = objects(measured, n)
        out.expected = objects(expected, n)
        if callable(text):
            out._texts = [text]
            out._block[:] = 0
            out._local[:] = np.arange(n)
        else:
            out._message = objects(list(text), n)
        return out

    @classmethod
    def of(cls, findings: Sequence[Finding]) -> FindingColumns:
        """Columns of Finding objects (each kept in `obj`: read from it)."""
        n = len(findings)
        out = cls(n)
        if not n:
            return out
        out.obj[:] = list(findings)
        out.refresh(np.arange(n))
        return out

    def refresh(self, idx: np.ndarray) -> None:
        """Copy the Finding objects of rows `idx` into the columns (after they changed)."""
        fs = self.obj[idx].tolist()
        self.t[idx] = [f.t for f in fs]
        self.t_rel[idx] = [np.nan if f.t_rel is None else f.t_rel for f in fs]
        self.node[idx] = [NONE if f.node is None else f.node for f in fs]
        self.cob_id[idx] = [NONE if f.cob_id is None else f.cob_id for f in fs]
        self.line[idx] = [NONE if f.line is None else f.line for f in fs]
        self.row[idx] = [f.row for f in fs]
        self.at_end[idx] = [f.at_end for f in fs]
        for name in (*_OBJS, "message"):
            col = self._message if name == "message" else getattr(self, name)
            col[idx] = objects([getattr(f, name) for f in fs], len(fs))
        self._block[idx] = NONE

    @classmethod
    def concat(cls, parts: Sequence[FindingColumns]) -> FindingColumns:
        parts = [p for p in parts if len(p)]
        if len(parts) == 1:
            return parts[0]
        out = cls(0)
        if not parts:
            return out
        for name in ("t", "t_rel", *_INTS, "at_end", *_OBJS, "obj", "_message", "_local"):
            setattr(out, name, np.concatenate([getattr(p, name) for p in parts]))
        blocks, texts = [], []
        for p in parts:
            blocks.append(np.where(p._block == NONE, NONE, p._block + len(texts)))
            texts.extend(p._texts)
        out._block = np.concatenate(blocks)
        out._texts = texts
        return out

    def take(self, idx) -> FindingColumns:
        """The findings at `idx` (an index array or a boolean mask), in that order."""
        out = FindingColumns(0)
        for name in ("t", "t_rel", *_INTS, "at_end", *_OBJS, "obj", "_message", "_local"):
            setattr(out, name, getattr(self, name)[idx])
        out._block = self._block[idx]
        out._texts = self._texts
        return out

    def sort(self) -> FindingColumns:
        """By time, then line (a log without timestamps), stable: emission order on ties."""
        if self.t.size < 2:
            return self
        if not (np.diff(self.t) <= 0).any():  # strictly increasing: nothing to do
            return self
        order = np.lexsort((np.where(self.line == NONE, 0, self.line), self.t))
        if not (np.diff(order) < 0).any():
            return self
        return self.take(order)

    # --- reading --------------------------------------------------------------
    @property
    def fails(self) -> np.ndarray:
        """Rows that fail a check run (info findings do not)."""
        sev = self.severity
        live = self._live()
        if live.size:
            sev = sev.copy()
            sev[live] = [self.obj[i].severity for i in live.tolist()]
        return ~np.asarray(sev == "info", bool)

    def _live(self) -> np.ndarray:
        """Rows read from their Finding object (emitted alone; it may have changed since)."""
        return np.flatnonzero(np.not_equal(self.obj, None))

    def messages(self, idx: np.ndarray | None = None) -> list[str]:
        """The messages of rows `idx` (all by default), built where not yet."""
        idx = np.arange(len(self)) if idx is None else np.asarray(idx, np.int64)
        todo = idx[self._block[idx] != NONE]
        if todo.size:
            blocks = self._block[todo]
            for b in np.unique(blocks).tolist():
                rows = todo[blocks == b]
                self._message[rows] = self._texts[b](self._local[rows])
                self._block[rows] = NONE
        out = self._message[idx]
        live = np.flatnonzero(np.not_equal(self.obj[idx], None))
        for k in live.tolist():
            out[k] = self.obj[idx[k]].message
        return out.tolist()

    def column(self, name: str) -> list:
        """One column of the findings table as Python values, as `Finding.record()` gives them."""
        if name == "message":
            return self.messages()
        if name in ("node", "cob_id", "line"):
            col = getattr(self, name)
            values = col.tolist()
            if (col == NONE).any():
                values = [None if v == NONE else v for v in values]
        elif name == "t_rel":
            values = round6(self.t_rel)
        elif name in ("measured", "expected"):
            values = getattr(self, name).tolist()  # tidy changes only floats and lists
            if not set(map(type, values)) <= {int, str}:
                values = [v if type(v) is int or type(v) is str else tidy(v) for v in values]
        else:
            values = getattr(self, name).tolist()
        for i in self._live().tolist():
            v = getattr(self.obj[i], name)
            values[i] = round(v, 6) if name == "t_rel" and v is not None else v
        return values

    def times(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The t and t_rel columns as `column` gives them, as float64 arrays; None when a
        row is read from its Finding or has no t_rel (None, not NaN): then read `column`."""
        if np.isnan(self.t_rel).any() or self._live().size:
            return None
        return self.t, rounded6(self.t_rel)

    def ints(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(values, missing) of node, cob_id or line, as `column` gives them."""
        values = getattr(self, name).copy()
        for i in self._live().tolist():
            v = getattr(self.obj[i], name)
            values[i] = NONE if v is None else v
        return values, values == NONE

    def records(self) -> list[dict]:
        """The JSON records (`Finding.record()`), every row."""
        cols = [self.column(c) for c in TABLE_COLUMNS]
        keys = ("kind", *TABLE_COLUMNS)
        kind = ["finding"] * len(self)
        out = [dict(zip(keys, r, strict=True)) for r in zip(kind, *cols, strict=True)]
        bus = self.column("bus")
        for i in np.flatnonzero(np.not_equal(np.asarray(bus, object), None)).tolist():
            out[i]["bus"] = bus[i]  # several buses: which one
        return out

    def finding(self, i: int, message: str | None = None) -> Finding:
        """Row i as a Finding (the object itself for a row emitted alone)."""
        f = self.obj[i]
        if f is not None:
            return f
        if message is None:
            message = self.messages(np.array([i]))[0]
        node, cob, line = int(self.node[i]), int(self.cob_id[i]), int(self.line[i])
        tr = float(self.t_rel[i])
        return Finding(
            float(self.t[i]),
            self.rule[i],
            self.severity[i],
            None if node == NONE else node,
            None if cob == NONE else cob,
            message,
            self.measured[i],
            self.expected[i],
            self.why[i],
            int(self.row[i]),
            None if tr != tr else tr,
            self.basis[i],
            None if line == NONE else line,
            bool(self.at_end[i]),
            self.bus[i],
        )

    def findings(self, idx: np.ndarray | None = None) -> list[Finding]:
        """Rows `idx` (all by default) as Finding objects, messages built in one go."""
        idx = np.arange(len(self)) if idx is None else np.asarray(idx, np.int64)
        texts = self.messages(idx)
        return [self.finding(i, m) for i, m in zip(idx.tolist(), texts, strict=True)]

    def __iter__(self) -> Iterator[Finding]:
        return iter(self.findings())

    def __getitem__(self, i: int) -> Finding:
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(i)
        return self.finding(i)

    def pairs(self) -> list[tuple[int, dict]]:
        """(row, record) as streamed outputs place them among a batch's records."""
        return list(zip(self.row.tolist(), self.records(), strict=True))
