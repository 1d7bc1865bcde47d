"""Stretches of frames under one configuration.

A rule judges each frame by the value in force at its time. Values change rarely (an
SDO write, a reset), so a rule asks its ConfigSource once per stretch between two
changes (usually once per batch), and leaves unjudged the one gap that spans a change:
which value the device followed across it is not known, and a guess could be a false
alarm.
"""

from __future__ import annotations

import numpy as np


def runs(changes: np.ndarray, t: np.ndarray) -> list[tuple[slice, float]]:
    """(slice, time to ask at) per run of consecutive frames with no change between them."""
    if t.size == 0:
        return []
    if changes.size == 0:
        return [(slice(0, t.size), float(t[0]))]
    k = np.searchsorted(changes, t, side="right")
    cuts = (np.flatnonzero(k[1:] != k[:-1]) + 1).tolist()
    bounds = [0, *cuts, t.size]
    return [(slice(a, b), float(t[a])) for a, b in zip(bounds, bounds[1:], strict=False)]


def crossing(changes: np.ndarray, prev: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Whether a change lies in each gap (prev, t]."""
    if changes.size == 0:
        return np.zeros(t.shape, bool)
    return np.searchsorted(changes, prev, side="right") != np.searchsorted(changes, t, side="right")


def per_frame(changes: np.ndarray, t: np.ndarray, lookup) -> list:
    """lookup(time) for every frame, asked once per run."""
    out: list = [None] * t.size
    for sl, at in runs(changes, t):
        out[sl] = [lookup(at)] * (sl.stop - sl.start)
    return out


def pdo_stretches(ctx, g) -> list:
    """Per COB-ID of a PDO gap table and stretch of its frames under one PDO configuration:
    (COB-ID, (node, PdoConfig), indices into the table, whether each gap is judged).

    Computed once per batch and table (three rules read it: a config lookup and a few
    arrays per COB-ID each); the readers index the arrays, never write them."""
    got = ctx.shared.get("pdo_stretches")
    if got is None or got[0] is not g:
        got = ctx.shared["pdo_stretches"] = (g, list(_pdo_stretches(ctx, g)))
    return got[1]


def _pdo_stretches(ctx, g):
    changes = ctx.config.pdo_changes()
    for cob, sl in g.groups():
        t = g.t[sl]
        across = crossing(changes, g.prev[sl], t)
        for run, at in runs(changes, t):
            cfg = ctx.config.pdo_params(cob, at)
            if cfg is not None:
                yield cob, cfg, np.arange(run.start, run.stop) + sl.start, ~across[run]


def sync_before(srows: np.ndarray, st: np.ndarray, rows: np.ndarray, carried: float) -> tuple:
    """(SYNCs of this batch before each row, time of the latest SYNC before each row): in
    this batch, else `carried`, the last one of earlier batches (NaN: none yet). A live
    batch often holds PDOs and no SYNC: never index an empty array."""
    k = np.searchsorted(srows, rows)
    last_t = np.full(k.size, carried)
    if st.size:
        last_t = np.where(k > 0, st[np.maximum(k - 1, 0)], last_t)
    return k, last_t
