"""The checks' per-batch shortcuts give exactly what the plain computation gives.

NMT states from the heartbeat gap table (not a sort of their own), the timing
statistics' steady-state path (a gap table with no first-ever frame uses its own
groups) and the PDO stretches computed once per batch, each against the way it
replaced, on seeded random batches with the edge cases (guard responses, keys first
seen mid-log, kept gaps). Run with and without the compiled helper.
"""

from __future__ import annotations

import numpy as np
import pytest

from cananalyze.checks.gaps import grouped_gaps
from cananalyze.checks.rule import Context, GapState
from cananalyze.checks.timing import Timing
from cananalyze.core.frames import FrameBatch
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.nmt_state import NmtStates
from cananalyze.protocol.services import Service


def _batch(rng, n: int, t0: float, guards: bool) -> DecodedBatch:
    """Heartbeats (and maybe guard responses) of nodes 1..9 among other traffic."""
    fb = FrameBatch.allocate(n)
    fb.t[:] = t0 + np.sort(rng.random(n))
    fb.data[:, 0] = rng.choice([0x00, 0x04, 0x05, 0x7F, 0x85], n)
    kinds = [Service.HEARTBEAT, Service.TPDO, Service.SYNC]
    if guards:
        kinds.append(Service.GUARD_RESPONSE)
    service = rng.choice(np.array(kinds, np.uint8), n)
    node = rng.integers(1, 10, n).astype(np.int16)
    node[service == Service.SYNC] = -1
    pdo = np.zeros(n, np.uint8)
    return DecodedBatch(fb, service, node, pdo)


class _Ctx(Context):
    """A Context whose heartbeat gap table is given (the Checker's, carried across batches)."""

    def __init__(self, batch: DecodedBatch, heartbeats) -> None:
        super().__init__(batch, None, NmtStates(), GapState())
        self._gaps["heartbeat"] = heartbeats


@pytest.mark.parametrize("seed", range(6))
def test_nmt_states_from_the_heartbeat_table_are_the_sorted_ones(seed):
    rng = np.random.default_rng(seed)
    plain, grouped = NmtStates(), NmtStates()
    last = np.full(128, np.nan)
    t0 = 0.0
    for k in range(8):
        b = _batch(rng, int(rng.integers(0, 400)), t0, guards=bool(k % 3 == 1))
        t0 += 1.0
        rows = np.flatnonzero(b.service == Service.HEARTBEAT)
        g = grouped_gaps(b.frames.t, b.node[rows], rows, last)
        plain.update(b)
        grouped.update(b, _Ctx(b, g))
    assert plain.times == grouped.times
    assert plain.states == grouped.states
    assert plain.sources == grouped.sources
    np.testing.assert_array_equal(plain._last, grouped._last)


def _tables(seed: int, batches: int):
    """PDO-like gap tables: keys appear mid-log (NaN gaps), some streams past 4096 gaps."""
    rng = np.random.default_rng(seed)
    last = np.full(2048, np.nan)
    t0, out = 0.0, []
    for k in range(batches):
        n = int(rng.integers(1, 6000))
        keys = rng.integers(0x181, 0x181 + 3 + 2 * k, n)
        t = t0 + np.sort(rng.random(n)) * 5.0
        t0 = float(t[-1])
        out.append(grouped_gaps(t, keys, np.arange(n), last))
    return out


def _plain_update_table(timing: Timing, name: str, g) -> None:
    """The update as it was: filter the NaN gaps, find the key runs by comparing keys."""
    from cananalyze.checks.streamstats import StreamStats

    gap = g.gap
    ok = ~np.isnan(gap)
    v, key = gap[ok] * 1000.0, g.key[ok]
    first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    keep = name in timing.keep
    if v.size and timing.with_stats:
        timing._add_stats(name, v, key, first, g.prev[ok], gap[ok], keep)
    elif v.size and keep:
        ends = np.r_[first[1:], v.size].tolist()
        for a, e, key_j in zip(first.tolist(), ends, key[first].tolist(), strict=True):
            timing.gaps[name].add(key_j, g.prev[ok][a:e], gap[ok][a:e])
    for key_j, sl in g.groups():
        if key_j not in timing.stats[name]:
            timing.stats[name][key_j] = StreamStats()
        timing.count[name][key_j] += sl.stop - sl.start
        sp = timing.span[name].get(key_j)
        if sp is None:
            timing.span[name][key_j] = [float(g.t[sl.start]), float(g.t[sl.stop - 1])]
        else:
            sp[1] = float(g.t[sl.stop - 1])


@pytest.mark.parametrize("stats", [True, False])
@pytest.mark.parametrize("keep", [True, False])
@pytest.mark.parametrize("seed", range(3))
def test_timing_steady_state_path_is_the_filtered_one(seed, keep, stats):
    fast = Timing(keep={"pdo"} if keep else set(), stats=stats)
    plain = Timing(keep={"pdo"} if keep else set(), stats=stats)
    for g in _tables(seed, 12):
        fast._update_table("pdo", g)
        _plain_update_table(plain, "pdo", g)
    assert fast.report() == plain.report()
    assert fast.lines() == plain.lines()
    assert fast.count == plain.count and fast.span == plain.span
    if keep:
        assert fast.gaps["pdo"].keys() == plain.gaps["pdo"].keys()
        for key in plain.gaps["pdo"].keys():
            for a, b in zip(fast.all_gaps("pdo", key), plain.all_gaps("pdo", key), strict=True):
                np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("seed", range(4))
def test_context_rows_are_the_rows_of_those_services(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 3000))
    codes = np.array([int(s) for s in Service] + [16, 200, 255], np.uint8)
    service = rng.choice(codes, n, p=None if seed % 2 else _skewed(codes.size))
    b = DecodedBatch(FrameBatch.allocate(n), service, np.zeros(n, np.int16), np.zeros(n, np.uint8))
    ctx = Context(b, None, NmtStates(), GapState())
    asks = [(s,) for s in Service] + [
        (Service.TPDO, Service.RPDO),
        (Service.GUARD_REQUEST, Service.GUARD_RESPONSE, Service.BOOTUP),
        (Service.SYNC, Service.EMCY, Service.NMT, Service.TIME),
        (Service.EMCY, Service.HEARTBEAT),
    ]
    for services in asks * 2:  # the second time from the cache
        got = ctx.rows(*services)
        want = np.flatnonzero(np.isin(service, np.array(services, np.uint8)))
        np.testing.assert_array_equal(got, want)
        assert got.dtype == want.dtype and not got.flags.writeable


def _skewed(k: int) -> np.ndarray:
    """Mostly bulk traffic (PDO, SDO, heartbeat), as a real bus."""
    p = np.ones(k)
    p[Service.TPDO : Service.HEARTBEAT + 1] = 60.0
    return p / p.sum()
