"""Gaps between successive frames per key (node or COB-ID), columnar and carried across batches.

Every timing rule needs "time since the previous frame of the same kind"; this
computes it once per batch with one stable sort, never a Python loop per frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Gaps:
    key: np.ndarray  # sorted keys
    t: np.ndarray  # frame time, grouped by key, in time order within a key
    prev: np.ndarray  # time of the previous frame of the same key (NaN: first ever)
    row: np.ndarray  # batch row of each frame
    starts: np.ndarray  # index of the first element of each key group

    @property
    def gap(self) -> np.ndarray:
        return self.t - self.prev

    def groups(self):
        """(key, slice) per key present in the batch: a loop over keys, not frames."""
        if self.key.size == 0:
            return
        ends = np.append(self.starts[1:], self.key.size)
        for s, e in zip(self.starts.tolist(), ends.tolist(), strict=True):
            yield int(self.key[s]), slice(s, e)


def grouped_gaps(t: np.ndarray, keys: np.ndarray, rows: np.ndarray, last: np.ndarray) -> Gaps:
    """Gaps for rows of a batch, by key; `last` (indexed by key) carries times between batches."""
    keys = keys.astype(np.intp)
    # keys are node-IDs or 11-bit COB-IDs: as uint16, numpy's stable sort is a radix sort
    small = keys.size and 0 <= keys.min() and keys.max() < 1 << 16
    order = np.argsort(keys.astype(np.uint16) if small else keys, kind="stable")
    k = keys[order]
    tt = t[rows][order]
    r = rows[order]
    first = np.ones(k.size, bool)
    first[1:] = k[1:] != k[:-1]
    prev = np.empty_like(tt)
    prev[1:] = tt[:-1]
    prev[first] = last[k[first]]
    end = np.ones(k.size, bool)
    end[:-1] = first[1:]
    last[k[end]] = tt[end]
    return Gaps(k, tt, prev, r, np.flatnonzero(first))
