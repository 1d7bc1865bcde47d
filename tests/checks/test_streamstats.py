"""Streaming timing statistics against numpy on every value: exact moments, quantiles within 0.5 %."""

from __future__ import annotations

import numpy as np
import pytest

from cananalyze.checks.streamstats import EXACT, MAX_BINS, StreamStats, stats_ms


def _fed(values: np.ndarray, batch: int) -> StreamStats:
    st = StreamStats()
    for i in range(0, values.size, batch):
        st.add(values[i : i + batch])
    return st


@pytest.mark.parametrize(
    "values",
    [
        np.random.default_rng(1).normal(10.0, 0.3, 50_000),  # a jittery 10 ms period
        np.random.default_rng(2).lognormal(0.0, 2.0, 30_000),  # latencies over decades
        np.r_[np.full(20_000, 100.0), np.full(50, 1600.0)],  # periodic with dropouts
        np.r_[np.zeros(9000), np.random.default_rng(3).uniform(0, 5, 9000)],  # zero gaps
    ],
)
def test_histogram_mode_against_numpy(values: np.ndarray) -> None:
    st = _fed(values, 6553)
    got, ref = st.stats(), stats_ms(values)
    assert got["count"] == ref["count"] == values.size
    assert got["min"] == ref["min"] and got["max"] == ref["max"]
    assert got["mean"] == pytest.approx(ref["mean"], rel=1e-9, abs=1e-12)
    assert got["jitter"] == pytest.approx(ref["jitter"], rel=1e-6, abs=1e-9)
    for q in ("median", "p99"):
        assert got[q] == pytest.approx(ref[q], rel=0.001 * 2**st._level, abs=1e-3), q


def test_periodic_stream_quantiles_are_exact() -> None:
    values = np.r_[np.full(10_000, 100.0), np.full(100, 1600.0)]
    got = _fed(values, 1000).stats()
    assert got["median"] == 100.0 and got["p99"] == 100.0 and got["max"] == 1600.0


def test_small_streams_are_exact_and_batching_does_not_matter() -> None:
    values = np.random.default_rng(4).exponential(3.0, EXACT)
    assert _fed(values, 7).stats() == stats_ms(values)
    big = np.random.default_rng(5).exponential(3.0, 3 * EXACT)
    a, b = _fed(big, 100).stats(), _fed(big, 5000).stats()
    assert a["count"] == b["count"]
    for q in ("median", "p99"):  # bin sums differ only in the order of additions
        assert a[q] == pytest.approx(b[q], rel=1e-12), q


def test_memory_does_not_grow_with_the_stream() -> None:
    st = StreamStats()
    rng = np.random.default_rng(6)
    for _ in range(200):
        st.add(rng.normal(10.0, 0.2, 10_000))
    assert st._exact is None and st._level == 0 and st._count.size < 200  # 0.1 % bins


def test_wide_streams_get_wider_bins_not_more() -> None:
    values = np.exp(np.random.default_rng(7).uniform(np.log(1e-2), np.log(1e7), 60_000))
    st = _fed(values, 4000)
    ref = stats_ms(values)
    assert st._level == 3 and st._count.size <= MAX_BINS  # 9 decades: 0.8 % bins
    for q in ("median", "p99"):
        assert st.stats()[q] == pytest.approx(ref[q], rel=0.008), q


def test_jitter_of_a_periodic_stream_is_resolved() -> None:
    # 100 ms period, 0.1 ms jitter: p99 must show the jitter, not the period
    values = 100.0 + np.random.default_rng(8).normal(0.0, 0.1, 20_000)
    got, ref = _fed(values, 3000).stats(), stats_ms(values)
    assert abs(got["p99"] - ref["p99"]) < 0.1 and got["p99"] > 100.15


def test_histogram_many_equals_one_stream_at_a_time() -> None:
    """Timing bins all streams of a batch with one bincount: bins, sums and levels as before."""
    from cananalyze.checks.streamstats import EXACT, StreamStats, bins_of, histogram_many

    rng = np.random.default_rng(7)
    one = [StreamStats() for _ in range(9)]
    many = [StreamStats() for _ in range(9)]
    for st in one + many:  # past EXACT: histogram mode
        st.add(np.full(EXACT + 1, 10.0))
    for batch in range(12):
        parts = []
        for j in range(9):
            n = int(rng.integers(1, 300))
            if j == 3:
                vals = rng.random(n) * 10 ** rng.integers(0, 7)  # wide: coarsens
            elif j == 5 and batch % 4 == 0:
                vals = np.r_[rng.random(n) * 5, 0.0, -0.5]  # below 1 us
            else:
                vals = 100.0 + rng.normal(0, 0.3 * (j + 1), n)
            parts.append(vals)
        v = np.concatenate(parts)
        b = bins_of(v)
        ends = np.cumsum([p.size for p in parts])
        starts = ends - [p.size for p in parts]
        for st, a, e in zip(one, starts, ends, strict=True):
            st.add_values(v[a:e], b[a:e])
        histogram_many(list(zip(many, starts.tolist(), ends.tolist(), strict=True)), v, b)
        for x, y in zip(one, many, strict=True):
            assert (x._level, x._lo, x._under) == (y._level, y._lo, y._under)
            assert np.array_equal(x._count, y._count) and np.array_equal(x._sum, y._sum)
    assert one[3]._level > 0 and one[5]._under[0] > 0


@pytest.mark.parametrize(
    "sizes, spread",
    [
        ((10, 20), 1.0),
        ((3000, 3000), 1.0),
        ((5000, 100), 1.0),
        ((100, 9000), 1.0),
        ((20000, 30000), 1.5),
    ],
)
def test_merged_streams_give_the_statistics_of_all_their_values(sizes, spread) -> None:
    """`merge` (the report's SDO latency over every node): the same count, moments and
    quantiles as one stream fed every value, in exact and histogram mode alike."""
    rng = np.random.default_rng(sum(sizes))
    a = rng.lognormal(3.0, spread, sizes[0])
    b = rng.lognormal(3.0, spread, sizes[1])
    b[:3] = 0.0  # below 1 us: the shared underflow bin
    one, left, right = StreamStats(), StreamStats(), StreamStats()
    for part in np.array_split(a, 3):
        one.add(part)
        left.add(part)
    for part in np.array_split(b, 3):
        one.add(part)
        right.add(part)
    left.merge(right)
    want, got = one.stats(), left.stats()
    assert got["count"] == want["count"] == sum(sizes)
    for k in ("min", "max", "median", "p99", "mean", "jitter"):
        assert got[k] == pytest.approx(want[k], rel=1e-9), k
    if sum(sizes) <= EXACT:  # still exact: numpy's values
        assert got["median"] == pytest.approx(np.median(np.concatenate((a, b))), rel=1e-12)


def test_merging_a_narrow_stream_into_a_wide_one_aligns_the_bins() -> None:
    """A stream coarsened by a wide spread merged with a fine one: every value counted,
    quantiles within the wider bins' width of numpy's."""
    rng = np.random.default_rng(5)
    wide = np.concatenate((rng.uniform(0.01, 1e7, 6000), [1e-2, 1e7]))
    narrow = rng.normal(100.0, 0.05, 9000)
    w, n = StreamStats(), StreamStats()
    w.add(wide)
    n.add(narrow)
    assert w._level > n._level  # the case: different bin widths
    for first, second in ((w, n), (n, w)):
        s = StreamStats()
        s.merge(first)
        s.merge(second)
        allv = np.concatenate((wide, narrow))
        assert s.n == allv.size and s.min == allv.min() and s.max == allv.max()
        assert s.bars()[2].sum() == allv.size
        assert s.quantile(0.5) == pytest.approx(np.median(allv), rel=0.01)


def test_bars_count_every_value_in_at_most_the_bars_asked() -> None:
    """The report's histogram of a stream: every value in one bar, the bar holding the
    largest value ends past it, in exact and histogram mode."""
    rng = np.random.default_rng(3)
    for size in (500, 200_000):
        v = rng.normal(100.0, 0.5, size)
        v[:10] = 1600.0
        v[10] = 0.0  # below 1 us
        s = StreamStats()
        for part in np.array_split(v, 7):
            s.add(part)
        left, width, count = s.bars(most=150)
        assert count.sum() == v.size and count.size <= 151  # (+ the underflow bar)
        assert (width > 0).all() and (np.diff(left) > 0).all()
        assert left[-1] <= 1600.0 < left[-1] + width[-1]
        assert left[0] < 1e-3  # the underflow bar below 1 us
        assert s.stats()["median"] == pytest.approx(np.median(v), rel=0.001)
