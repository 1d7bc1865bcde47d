"""Gaps between successive frames per key (node or COB-ID), columnar and carried across batches.

Every timing rule needs "time since the previous frame of the same kind"; this
computes it once per batch with one stable sort, never a Python loop per frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from cananalyze.core.columns.order import stable_order
from cananalyze.runtime.speedups import C


@dataclass
class Gaps:
    key: np.ndarray  # sorted keys
    t: np.ndarray  # frame time, grouped by key, in time order within a key
    prev: np.ndarray  # time of the previous frame of the same key (NaN: first ever)
    row: np.ndarray  # batch row of each frame
    starts: np.ndarray  # index of the first element of each key group

    @cached_property
    def gap(self) -> np.ndarray:
        """t - prev, computed once for every rule and the timing that read it (read-only:
        shared)."""
        gap = self.t - self.prev
        gap.flags.writeable = False
        return gap

    def groups(self):
        """(key, slice) per key present in the batch: a loop over keys, not frames."""
        if self.key.size == 0:
            return
        starts = self.starts.tolist()
        # the keys as one list, not a numpy scalar per group (a PDO table has hundreds)
        for key, s, e in zip(
            self.key[self.starts].tolist(), starts, starts[1:] + [self.key.size], strict=True
        ):
            yield key, slice(s, e)


def grouped_gaps(t: np.ndarray, keys: np.ndarray, rows: np.ndarray, last: np.ndarray) -> Gaps:
    """Gaps for rows of a batch, by key; `last` (indexed by key) carries times between batches."""
    # keys are node-IDs or 11-bit COB-IDs: a counting sort (or numpy's radix sort) as uint16
    top = int(keys.max()) if keys.size else 0
    small = keys.size and 0 <= keys.min() and top < 1 << 16
    if small and top < last.size and keys.size >= 64 and getattr(C, "group_gaps", None):
        return _grouped_compiled(t, keys, rows, last)
    order = stable_order(keys, top) if small else np.argsort(keys, kind="stable")
    k = keys[order].astype(np.intp)  # the cast after the gather: one pass over the sorted keys
    r = rows[order]
    tt = t[r]  # one gather of the times, not the rows' times then their order
    first = np.ones(k.size, bool)
    first[1:] = k[1:] != k[:-1]
    prev = np.empty_like(tt)
    prev[1:] = tt[:-1]
    prev[first] = last[k[first]]
    end = np.ones(k.size, bool)
    end[:-1] = first[1:]
    last[k[end]] = tt[end]
    return Gaps(k, tt, prev, r, np.flatnonzero(first))


def _grouped_compiled(t: np.ndarray, keys: np.ndarray, rows: np.ndarray, last: np.ndarray) -> Gaps:
    """`grouped_gaps` as one counting sort that gathers and carries as it goes (the
    compiled helper): the same Gaps, without numpy's sort and four gathers."""
    n = keys.size
    k, r = np.empty(n, np.intp), np.empty(n, np.intp)
    tt, prev = np.empty(n, np.float64), np.empty(n, np.float64)
    starts = np.empty(last.size, np.intp)
    groups = C.group_gaps(
        np.ascontiguousarray(keys, np.uint16),
        np.ascontiguousarray(rows, np.intp),
        np.ascontiguousarray(t, np.float64),
        last,
        k,
        tt,
        prev,
        r,
        starts,
    )
    return Gaps(k, tt, prev, r, starts[:groups].copy())
