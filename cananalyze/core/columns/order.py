"""The stable sort order of small integer keys (COB-IDs, node-IDs), the decode path's grouping,
and values numbered in the order they first come (`first_seen_codes`).

Rows are grouped by key (the gap tables by node or COB-ID, the PDO decoder by
segment and COB-ID) with one stable sort per batch. With the compiled helper it is
a counting sort (a hundred distinct keys: one count and one scatter pass); without,
numpy's stable argsort of uint16 (a radix sort). A stable order is unique, so both
give the same rows.
"""

from __future__ import annotations

import numpy as np

from cananalyze.runtime.speedups import C


def stable_order(keys: np.ndarray, top: int | None = None) -> np.ndarray:
    """np.argsort(keys, kind="stable") for integer keys in 0..65535; `top`: max(keys) if known."""
    k16 = keys.astype(np.uint16, copy=False)
    if C is None or keys.size < 64:
        return np.argsort(k16, kind="stable")
    if top is None:
        top = int(k16.max())
    order = np.empty(keys.size, np.intp)
    C.stable_order(np.ascontiguousarray(k16), top + 1, order)
    return order


def first_seen_codes(values) -> tuple[np.ndarray, list]:
    """Each value's number among the distinct values, numbered in the order they first come
    (pandas.factorize without sorting), and those distinct values."""
    code: dict = {}
    out = np.fromiter((code.setdefault(v, len(code)) for v in values), np.int64, len(values))
    return out, list(code)
