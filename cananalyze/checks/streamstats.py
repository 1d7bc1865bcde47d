"""Timing statistics of one stream (gaps, latencies) in memory that does not grow with the log.

count, min, max, mean and jitter (population standard deviation) are exact
running values: batch moments merged with Chan et al.'s parallel formula.
The median and p99 come from the values themselves while a stream has at most
`EXACT` of them (exact, as numpy computes them), and after that from a
log-scale histogram: bins 0.5 % wide from 1 us up, each remembering the count and
the sum of its values. A quantile is the mean of the values in the bin of its
rank (interpolated between ranks like numpy), clamped to [min, max], so it is
within 0.5 % of the exact value, and exact when a bin holds one repeated value
(a clean periodic stream). Values below 1 us (0, or negative in an unsorted
log) share one bin and are exact to 1 us. Memory: the bins a stream touches,
a few dozen for a periodic stream.
"""

from __future__ import annotations

import math

import numpy as np

EXACT = 4096  # values kept as they are before the histogram takes over
RATIO = 1.005  # bin width: a quantile is within 0.5 % of its exact value
_FLOOR = 1e-3  # ms: 1 us; values below share bin 0
_LOG_R = math.log(RATIO)


def bins_of(v: np.ndarray) -> np.ndarray:
    """Bin of each value (ms): 0 below 1 us, else 1 + floor(log_r(v / 1 us))."""
    b = np.zeros(v.size, np.int64)
    pos = v >= _FLOOR
    b[pos] = 1 + np.floor(np.log(v[pos] / _FLOOR) / _LOG_R).astype(np.int64)
    return b


class StreamStats:
    """Running statistics of one stream of values in ms (see the module docstring)."""

    __slots__ = ("n", "min", "max", "mean", "m2", "_exact", "_lo", "_count", "_sum")

    def __init__(self) -> None:
        self.n = 0
        self.min = math.inf
        self.max = -math.inf
        self.mean = 0.0
        self.m2 = 0.0
        self._exact: list[np.ndarray] | None = []  # None once the histogram took over
        self._lo = 0  # bin of _count[0]
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
        lo, hi = int(b.min()), int(b.max())
        if self._count.size == 0:
            self._lo = lo
        new_lo = min(lo, self._lo)
        new_hi = max(hi, self._lo + self._count.size - 1)
        if new_lo != self._lo or new_hi - new_lo + 1 != self._count.size:
            size = new_hi - new_lo + 1
            count, total = np.zeros(size, np.int64), np.zeros(size, np.float64)
            at = self._lo - new_lo
            count[at : at + self._count.size] = self._count
            total[at : at + self._count.size] = self._sum
            self._lo, self._count, self._sum = new_lo, count, total
        size = self._count.size
        self._count += np.bincount(b - self._lo, minlength=size)
        self._sum += np.bincount(b - self._lo, weights=v, minlength=size)

    def _ranks(self, ranks: list[int]) -> list[float]:
        """Approximate value of the sorted stream at each 0-based rank (histogram mode)."""
        cum = np.cumsum(self._count)
        out = []
        for r in ranks:
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
            from .timing import stats_ms

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
