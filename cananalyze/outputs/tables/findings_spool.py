"""An export's findings kept on disk until the end, then read back by time, a chunk at a time.

The findings table is by time, and a rule that judges a span (a heartbeat dropout)
reports after later findings were emitted, so the table can only be written when
the log has ended. Held in memory, the findings were the one part of an export
that grew with the log: a healthy 50M-frame bus has ~235k EMCY warnings, whose
strings and columns took ~100 MB (peak 233 MB at 5M frames, 420 MB at 50M). Here
each block of rows is pickled to a temporary file as it fills; only the times stay
in memory (8 bytes a row) for the one stable sort at the end.

A row emitted alone keeps its `Finding` object (`FindingColumns.obj`): live, a
silence's finding is completed when the silence ends, after its batch was spooled.
Those objects (few: stateful rules) stay in memory and are put back on their rows
when a block is read, so the table shows them as they are at the end.
"""

from __future__ import annotations

import pickle
import tempfile
from collections import OrderedDict
from pathlib import Path

import numpy as np

from cananalyze.core.finding_columns import NONE, FindingColumns

BLOCK = 8192  # rows pickled together (pickle's per-call cost, and its memo of repeated texts)
CACHED = 4  # blocks held while the sorted chunks are read (a late finding's block)
# (a block leaves as soon as the order has no row of it further on: by time, a log's
# findings mostly come block after block)
# the columns a block is stored by (messages built: their builders are closures)
_FIELDS = tuple(
    n for n in FindingColumns.__slots__ if n not in ("obj", "_texts", "_block", "_local")
)


class FindingsSpool:
    """Findings in emission order on disk; `chunk(start, size)` gives rows of the time order."""

    def __init__(self, where: Path | str) -> None:
        self._file = tempfile.TemporaryFile(dir=where, prefix=".findings-spool.")
        self._offsets: list[int] = []  # each spooled block's place in the file
        self._starts: list[int] = [0]  # each block's first row (and the end)
        self._t: list[np.ndarray] = []  # each block's times
        self._live: list[tuple[int, object]] = []  # (row, its Finding) of rows emitted alone
        self._pending: list[FindingColumns] = []
        self._pending_rows = 0
        self.named = False  # a row names its bus (several buses)
        self._order: np.ndarray | None = None
        self._last = np.zeros(0, np.int64)  # each block's last place in the order
        self._cache: OrderedDict[int, FindingColumns] = OrderedDict()

    def __len__(self) -> int:
        return self._starts[-1] + self._pending_rows

    def add(self, found: FindingColumns) -> None:
        if not len(found):
            return
        found.messages()  # built now (the event log built most already), kept as text
        self.named = self.named or bool(np.not_equal(found.bus, None).any())
        self._pending.append(found)
        self._pending_rows += len(found)
        if self._pending_rows >= BLOCK:
            self._spill()

    def _spill(self) -> None:
        if not self._pending:
            return
        block = FindingColumns.concat(self._pending)
        self._pending, self._pending_rows = [], 0
        start = self._starts[-1]
        for i in np.flatnonzero(np.not_equal(block.obj, None)).tolist():
            self._live.append((start + i, block.obj[i]))
        self._t.append(np.array(block.t, np.float64))  # a copy: the batch's array may go
        self._offsets.append(self._file.tell())
        state = {n: getattr(block, n) for n in _FIELDS}
        pickle.dump(state, self._file, pickle.HIGHEST_PROTOCOL)
        self._starts.append(start + len(block))

    def _load(self, b: int) -> FindingColumns:
        """Block `b` as it was spooled, its live rows reading their Finding again."""
        got = self._cache.get(b)
        if got is not None:
            self._cache.move_to_end(b)
            return got
        self._file.seek(self._offsets[b])
        state = pickle.load(self._file)
        block = FindingColumns(0)
        for n, v in state.items():
            setattr(block, n, v)
        size = len(block)
        block.obj = np.empty(size, object)
        block._block = np.full(size, NONE, np.int64)  # every message built
        block._local = np.zeros(size, np.int64)
        start, end = self._starts[b], self._starts[b + 1]
        for row, f in self._live:
            if start <= row < end:
                block.obj[row - start] = f
        self._cache[b] = block
        if len(self._cache) > CACHED:
            self._cache.popitem(last=False)
        return block

    def order(self) -> np.ndarray:
        """Every row by time (stable: emission order on ties), live rows at their time now."""
        if self._order is None:
            self._spill()
            t = np.concatenate(self._t) if self._t else np.zeros(0)
            for row, f in self._live:
                t[row] = f.t
            self._order = np.argsort(t, kind="stable")
            # each block's last place in that order: after it, the block leaves the cache
            block = np.searchsorted(self._starts, self._order, "right") - 1
            self._last = np.full(len(self._offsets), -1, np.int64)
            np.maximum.at(self._last, block, np.arange(block.size))
        return self._order

    def chunk(self, start: int, size: int) -> FindingColumns:
        """Rows `start` to `start + size` of the time order."""
        picked = self.order()[start : start + size]
        blocks = np.searchsorted(self._starts, picked, "right") - 1
        pieces, places = [], []
        for b in np.unique(blocks).tolist():
            mine = np.flatnonzero(blocks == b)
            pieces.append(self._load(b).take(picked[mine] - self._starts[b]))
            places.append(mine)
            if self._last[b] < start + size:  # no row of it further on (until a re-read)
                self._cache.pop(b, None)
        if len(pieces) == 1:
            return pieces[0]
        out = FindingColumns.concat(pieces)
        return out.take(np.argsort(np.concatenate(places)))

    def close(self) -> None:
        self._file.close()
        self._cache.clear()
        self._live = []
