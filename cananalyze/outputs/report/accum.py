"""Bounded accumulators for the report: plotted series decimated, statistics exact.

An hour-long log has tens of millions of frames; the page may hold a few thousand
points per plot. `Envelope` keeps min and max per time bucket (a pixel column of
the plot), doubling the bucket width and merging neighbours when the log outgrows
its buckets, so memory is fixed and no peak is lost. Periods and latencies are
counted by `checks.streamstats.StreamStats`, the computation `--summary` prints, so
the page and the summary give the same numbers.
"""

from __future__ import annotations

import numpy as np

BUCKETS = 1000  # points across a plot: about one per pixel column


class Envelope:
    """Min/max of a value per time bucket, over the whole log, in fixed memory."""

    def __init__(self, buckets: int = BUCKETS, width: float = 0.001) -> None:
        self.n = buckets
        self.width = width
        self.t0: float | None = None
        self.lo = np.full(buckets, np.inf)
        self.hi = np.full(buckets, -np.inf)
        self.count = 0

    def add(self, t: np.ndarray, v: np.ndarray) -> None:
        t = np.asarray(t, np.float64)
        v = np.asarray(v, np.float64)
        ok = np.isfinite(v) & np.isfinite(t)
        if not ok.all():
            t, v = t[ok], v[ok]
        if t.size == 0:
            return
        if self.t0 is None:
            self.t0 = float(t.min())
        early = t < self.t0
        if early.any():  # out of order before the first bucket: clamp into it
            t = np.where(early, self.t0, t)
        idx = ((t - self.t0) / self.width).astype(np.int64)
        top = int(idx.max())
        while top >= self.n:
            self._coarsen()
            idx >>= 1
            top >>= 1
        np.minimum.at(self.lo, idx, v)
        np.maximum.at(self.hi, idx, v)
        self.count += t.size

    def _coarsen(self) -> None:
        """Twice the bucket width: neighbouring buckets merge."""
        self.width *= 2
        for arr, f in ((self.lo, np.minimum), (self.hi, np.maximum)):
            merged = f(arr[0::2], arr[1::2])
            arr[: merged.size] = merged
            arr[merged.size :] = np.inf if f is np.minimum else -np.inf

    def points(self, most: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(t, value) through each bucket's min and max, in time order: the envelope a
        plot of every value would draw at this width. `most`: at most this many buckets,
        neighbours merged (a plot's point budget shared by its lines, or half a page)."""
        lo, hi, width = self.lo, self.hi, self.width
        if most is not None and most < self.n:
            g = -(-self.n // most)
            pad = -self.n % g
            lo = np.concatenate((lo, np.full(pad, np.inf))).reshape(-1, g).min(axis=1)
            hi = np.concatenate((hi, np.full(pad, -np.inf))).reshape(-1, g).max(axis=1)
            width = width * g
        used = np.flatnonzero(hi >= lo)
        if used.size == 0 or self.t0 is None:
            return np.zeros(0), np.zeros(0)
        t = self.t0 + (used + 0.5) * width
        same = lo[used] == hi[used]
        tt = np.repeat(t, 2)
        vv = np.column_stack((lo[used], hi[used])).ravel()
        keep = np.ones(tt.size, bool)
        keep[1::2] = ~same  # a bucket with one value: one point
        return tt[keep], vv[keep]


class WindowSums:
    """Bits per fixed window (bus load), streamed: each finished window's load goes to
    an Envelope (so peaks survive decimation), and the exact peak is kept."""

    def __init__(self, window: float = 0.1) -> None:
        self.window = window
        self.t0: float | None = None
        self.pending: tuple[int, float] | None = None  # (window index, bits so far)
        self.load = Envelope()
        self.peak = 0.0
        self.bits = 0.0
        self.t_last: float | None = None

    def add(self, t: np.ndarray, bits: np.ndarray) -> None:
        ok = np.isfinite(t)
        if not ok.all():
            t, bits = t[ok], bits[ok]
        if t.size == 0:
            return
        if self.t0 is None:
            self.t0 = float(t[0])
        self.bits += float(bits.sum())
        self.t_last = float(t.max()) if self.t_last is None else max(self.t_last, float(t.max()))
        idx = np.maximum(np.floor((t - self.t0) / self.window), 0).astype(np.int64)
        # windows that have frames only: a log whose clock jumps by years costs nothing
        windows, inverse = np.unique(idx, return_inverse=True)
        sums = np.bincount(inverse, weights=bits).astype(np.float64)
        if self.pending is not None:
            k, s = self.pending
            at = int(np.searchsorted(windows, k))
            if at < windows.size and windows[at] == k:
                sums[at] += s
            else:
                self._emit(np.array([k]), np.array([s]))
        self._emit(windows[:-1], sums[:-1])
        self.pending = (int(windows[-1]), float(sums[-1]))

    def _emit(self, k: np.ndarray, s: np.ndarray) -> None:
        if k.size == 0:
            return
        per_s = s / self.window
        self.peak = max(self.peak, float(per_s.max()))
        self.load.add(self.t0 + (k + 0.5) * self.window, per_s)

    def finish(self) -> None:
        if self.pending is not None:
            k, s = self.pending
            start = self.t0 + k * self.window
            width = max(min((self.t_last or start) - start, self.window), self.window / 2)
            self.load.add(np.array([start + width / 2]), np.array([s / width]))
            self.pending = None

    @property
    def mean(self) -> float:
        if self.t0 is None or self.t_last is None or self.t_last <= self.t0:
            return 0.0
        return self.bits / (self.t_last - self.t0)
