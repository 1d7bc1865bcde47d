"""Timing statistics of one stream (gaps, latencies) in memory that does not grow with the log.

count, min, max, mean and jitter (population standard deviation) are exact
running values: batch moments merged with Chan et al.'s parallel formula.
The median and p99 come from the values themselves while a stream has at most
`EXACT` of them (exact, as numpy computes them), and after that from a
log-scale histogram of bins 0.1 % wide from 1 us up, each remembering the count
and the sum of its values. A quantile is the mean of the values in the bin of
its rank (interpolated between ranks like numpy), clamped to [min, max]: within
one bin width (0.1 %) of the exact value, and exact when a bin holds one
repeated value (a clean periodic stream). A stream whose values would need more
than `MAX_BINS` bins gets bins twice as wide (0.2 %, 0.4 %, ...): values from
1 us to 1 s stay within 0.4 %, to 3 hours within 0.8 %. Values below 1 us (0,
or negative in an unsorted log) share one extra bin. Memory: at most
`MAX_BINS` bins per stream, a few dozen for a periodic one.
"""

from __future__ import annotations

import math

import numpy as np

EXACT = 4096  # values kept as they are before the histogram takes over
RATIO = 1.001  # finest bin width: 0.1 %
MAX_BINS = 4096  # per stream; wider bins beyond that
_FLOOR = 1e-3  # ms: 1 us; values below share the underflow bin
_LOG_R = math.log(RATIO)


def bins_of(v: np.ndarray) -> np.ndarray:
    """Finest bin of each value (ms): -1 below 1 us, else floor(log_r(v / 1 us))."""
    pos = v >= _FLOOR
    if pos.all():  # the usual case: no value below 1 us, no mask; the same steps in place
        x = np.divide(v, _FLOOR)
        np.log(x, out=x)
        np.divide(x, _LOG_R, out=x)
        np.floor(x, out=x)
        return x.astype(np.int64)
    b = np.full(v.size, -1, np.int64)
    b[pos] = np.floor(np.log(v[pos] / _FLOOR) / _LOG_R).astype(np.int64)
    return b


class StreamStats:
    """Running statistics of one stream of values in ms (see the module docstring)."""

    __slots__ = (
        "n",
        "min",
        "max",
        "mean",
        "m2",
        "_exact",
        "_level",
        "_lo",
        "_count",
        "_sum",
        "_under",
    )

    def __init__(self) -> None:
        self.n = 0
        self.min = math.inf
        self.max = -math.inf
        self.mean = 0.0
        self.m2 = 0.0
        self._exact: list[np.ndarray] | None = []  # None once the histogram took over
        self._level = 0  # bins are 2**level finest bins wide
        self._lo = 0  # bin of _count[0]
        self._under = [0, 0.0]  # count and sum of the values below 1 us
        self._count = np.zeros(0, np.int64)
        self._sum = np.zeros(0, np.float64)

    def add(self, values_ms: np.ndarray) -> None:
        v = np.asarray(values_ms, np.float64)
        if v.size == 0:
            return
        mean = float(v.mean())
        self.add_moments(
            v.size, mean, float(((v - mean) ** 2).sum()), float(v.min()), float(v.max())
        )
        self.add_values(v)

    def add_moments(self, k: int, mean_b: float, m2_b: float, lo: float, hi: float) -> None:
        """Merge a batch's count, mean, sum of squared deviations, min and max (Chan et al.)."""
        n = self.n + k
        delta = mean_b - self.mean
        self.mean += delta * k / n
        self.m2 += m2_b + delta * delta * self.n * k / n
        self.n = n
        self.min = min(self.min, lo)
        self.max = max(self.max, hi)

    @property
    def exact(self) -> bool:
        """Whether the values are still kept as they are (the histogram has not taken over)."""
        return self._exact is not None

    def add_values(self, v: np.ndarray, bins: np.ndarray | None = None) -> None:
        """The same batch's values, for the quantiles (after `add_moments`); `bins` = `bins_of(v)`."""
        if self._exact is not None:
            self._exact.append(v.copy())
            if self.n <= EXACT:
                return
            v, bins = np.concatenate(self._exact), None
            self._exact = None
        self._histogram(v, bins)

    def _histogram(self, v: np.ndarray, b: np.ndarray | None) -> None:
        if b is None:
            b = bins_of(v)
        under = b < 0
        if under.any():
            self._under[0] += int(under.sum())
            self._under[1] += float(v[under].sum())
            v, b = v[~under], b[~under]
            if v.size == 0:
                return
        b = b >> self._level
        shift = self._fit(int(b.min()), int(b.max()))
        if shift:
            b = b >> shift
        size = self._count.size
        self._count += np.bincount(b - self._lo, minlength=size)
        self._sum += np.bincount(b - self._lo, weights=v, minlength=size)

    def _fit(self, lo: int, hi: int) -> int:
        """Make room for bins lo..hi (at the current level); return the coarsenings needed."""
        if self._count.size == 0:
            self._lo = lo
        new_lo = min(lo, self._lo)
        new_hi = max(hi, self._lo + self._count.size - 1)
        shift = 0
        while new_hi - new_lo + 1 > MAX_BINS:  # too wide a spread: bins twice as wide
            self._coarsen()
            shift += 1
            new_lo, new_hi = new_lo >> 1, new_hi >> 1
        if new_lo != self._lo or new_hi - new_lo + 1 != self._count.size:
            size = new_hi - new_lo + 1
            count, total = np.zeros(size, np.int64), np.zeros(size, np.float64)
            at = self._lo - new_lo
            count[at : at + self._count.size] = self._count
            total[at : at + self._count.size] = self._sum
            self._lo, self._count, self._sum = new_lo, count, total
        return shift

    def _coarsen(self) -> None:
        """Merge neighbouring bins: level + 1."""
        self._level += 1
        self._count, self._sum, self._lo = _coarser(self._count, self._sum, self._lo, 1)

    def _ranks(self, ranks: list[int]) -> list[float]:
        """Approximate value of the sorted stream at each 0-based rank (histogram mode)."""
        under_n, under_sum = self._under
        cum = under_n + np.cumsum(self._count)
        out = []
        for r in ranks:
            if r < under_n:
                out.append(under_sum / under_n)
                continue
            i = int(np.searchsorted(cum, r, side="right"))
            out.append(float(self._sum[i] / self._count[i]))
        return out

    def quantile(self, q: float) -> float:
        """The q-quantile (0..1), linear interpolation between ranks like numpy's default."""
        if self._exact is not None:
            return float(np.quantile(np.concatenate(self._exact), q))
        h = (self.n - 1) * q
        k = math.floor(h)
        a, b = self._ranks([k, min(k + 1, self.n - 1)])
        value = a + (h - k) * (b - a)
        return min(max(value, self.min), self.max)

    def stats(self) -> dict:
        """count, min, median, mean, p99, max, jitter: the keys of `timing.stats`."""
        if self.n == 0:
            return {"count": 0}
        if self._exact is not None:
            return stats_ms(np.concatenate(self._exact))
        return {
            "count": self.n,
            "min": self.min,
            "median": self.quantile(0.5),
            "mean": self.mean,
            "p99": self.quantile(0.99),
            "max": self.max,
            "jitter": math.sqrt(max(self.m2, 0.0) / self.n),
        }

    def merge(self, other: StreamStats) -> None:
        """Add another stream's values (the report's per-node SDO latencies into one)."""
        if other.n == 0:
            return
        self.add_moments(other.n, other.mean, other.m2, other.min, other.max)
        if other._exact is not None:
            self.add_values(np.concatenate(other._exact))
            return
        if self._exact is not None:  # the other is past EXACT values: so is the sum
            mine, self._exact = self._exact, None
            if mine:
                self._histogram(np.concatenate(mine), None)
        self._under = [self._under[0] + other._under[0], self._under[1] + other._under[1]]
        count, total, lo, level = other._count, other._sum, other._lo, other._level
        while self._level < level:
            self._coarsen()
        count, total, lo = _coarser(count, total, lo, self._level - level)
        if count.size == 0:
            return
        count, total, lo = _coarser(count, total, lo, self._fit(lo, lo + count.size - 1))
        at = lo - self._lo
        self._count[at : at + count.size] += count
        self._sum[at : at + count.size] += total

    def bars(self, most: int = 150) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(left edge, width, count) in ms of the non-empty histogram bars, neighbouring
        bins merged so that the range seen has at most `most` bars: the report's plot of
        the same values whose quantiles `stats` gives. Values below 1 us share the bar
        just below 1 us."""
        if self._exact is not None:
            v = np.concatenate(self._exact) if self._exact else np.zeros(0)
            b = bins_of(v)
            under = int((b < 0).sum())
            b = b[b >= 0]
            lo = int(b.min()) if b.size else 0
            count = np.bincount(b - lo) if b.size else np.zeros(0, np.int64)
            level = 0
        else:
            under, count, lo, level = self._under[0], self._count, self._lo, self._level
        nz = np.flatnonzero(count)
        lefts, widths, counts = [], [], []
        if under:
            lefts.append(np.array([_FLOOR / 2]))
            widths.append(np.array([_FLOOR / 2]))
            counts.append(np.array([under], np.int64))
        if nz.size:
            g = max(1, -(-(int(nz[-1]) - int(nz[0]) + 1) // most))
            group = (nz - nz[0]) // g
            merged = np.bincount(group, weights=count[nz]).astype(np.int64)
            k = np.flatnonzero(merged)
            first = lo + nz[0] + k * g  # bin numbers at `level`
            scale = float(1 << level)
            left = _FLOOR * np.exp(_LOG_R * first * scale)
            right = _FLOOR * np.exp(_LOG_R * (first + g) * scale)
            lefts.append(left)
            widths.append(right - left)
            counts.append(merged[k])
        if not counts:
            return np.zeros(0), np.zeros(0), np.zeros(0, np.int64)
        return np.concatenate(lefts), np.concatenate(widths), np.concatenate(counts)


def _coarser(count: np.ndarray, total: np.ndarray, lo: int, times: int) -> tuple:
    """Bins `times` levels wider, neighbours merged (`StreamStats._coarsen`, `merge`)."""
    for _ in range(times):
        if count.size:
            j = (lo + np.arange(count.size)) >> 1
            first = int(j[0])
            count = np.bincount(j - first, weights=count).astype(np.int64)
            total = np.bincount(j - first, weights=total)
            lo = first
        else:
            lo >>= 1
    return count, total, lo


def histogram_many(items: list[tuple[StreamStats, int, int]], v: np.ndarray, b: np.ndarray) -> None:
    """`add_values(v[a:e], b[a:e])` for many streams already in histogram mode, at once.

    One bincount for all of them instead of a dozen numpy calls per stream and batch
    (a bus has hundreds of PDO streams). Each bin's values are still summed in the
    same order, so the result is the same; a stream with values below 1 us goes the
    one-by-one way.
    """
    many = [x for x in items if x[2] > x[1]]
    if len(many) < 2:
        for st, a, e in many:
            st.add_values(v[a:e], b[a:e])
        return
    starts = np.array([a for _, a, _ in many], np.int64)
    k = np.array([e - a for _, a, e in many], np.int64)
    first = np.zeros(len(many), np.int64)
    first[1:] = np.cumsum(k)[:-1]
    if starts[0] == 0 and np.array_equal(starts, first) and int(k.sum()) == v.size:
        vv, bb = v, b  # the streams tile the table (the steady state): no gather
    else:
        idx = np.repeat(starts - first, k) + np.arange(int(k.sum()))
        vv, bb = v[idx], b[idx]
    low = np.minimum.reduceat(bb, first)
    level = np.array([st._level for st, _, _ in many], np.int64)
    same = bool((level == level[0]).all())
    sb = bb >> (int(level[0]) if same else np.repeat(level, k))
    lo = np.minimum.reduceat(sb, first).tolist()
    hi = np.maximum.reduceat(sb, first).tolist()
    together = np.ones(len(many), bool)
    for j, (st, a, e) in enumerate(many):
        if low[j] < 0:
            together[j] = False
            st._histogram(v[a:e], b[a:e])  # values below 1 us: summed as before
        elif st._fit(lo[j], hi[j]):
            together[j] = False  # coarsened: this stream's bins shift again
            st._count += np.bincount(
                (sb[first[j] : first[j] + k[j]] >> (st._level - level[j])) - st._lo,
                minlength=st._count.size,
            )
            st._sum += np.bincount(
                (sb[first[j] : first[j] + k[j]] >> (st._level - level[j])) - st._lo,
                weights=vv[first[j] : first[j] + k[j]],
                minlength=st._count.size,
            )
    use = np.flatnonzero(together)
    if use.size == 0:
        return
    sizes = np.array([many[j][0]._count.size for j in use.tolist()], np.int64)
    offset = np.zeros(use.size, np.int64)
    offset[1:] = np.cumsum(sizes)[:-1]
    base = np.zeros(len(many), np.int64)
    base[use] = offset - np.array([many[j][0]._lo for j in use.tolist()], np.int64)
    gidx = sb + np.repeat(base, k)
    weights = vv
    if use.size < len(many):
        keep = np.repeat(together, k)
        gidx, weights = gidx[keep], vv[keep]
    total = int(sizes.sum())
    counts = np.bincount(gidx, minlength=total)
    sums = np.bincount(gidx, weights=weights, minlength=total)
    for j, off, size in zip(use.tolist(), offset.tolist(), sizes.tolist(), strict=True):
        st = many[j][0]
        st._count += counts[off : off + size]
        st._sum += sums[off : off + size]


def stats(gaps_s: np.ndarray) -> dict:
    """count, min, median, mean, p99, max and jitter (standard deviation), in ms."""
    return stats_ms(gaps_s * 1000.0)


def stats_ms(g: np.ndarray) -> dict:
    """`stats` of values already in ms (exact: from every value)."""
    if g.size == 0:
        return {"count": 0}
    return {
        "count": int(g.size),
        "min": float(g.min()),
        "median": float(np.median(g)),
        "mean": float(g.mean()),
        "p99": float(np.percentile(g, 99)),
        "max": float(g.max()),
        "jitter": float(g.std()),
    }
