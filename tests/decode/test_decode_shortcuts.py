"""The decode path's shortcuts give exactly what the plain computation gives.

Each shortcut (a counting sort, a count per frame shape, a count per (service, node),
one NMT state per node and batch, the last EMCY per node as columns) is compared
with the computation it replaced, on seeded random columns with the edge cases the
real logs lack, and on a real candump log's identifiers. Run with and without the
compiled helper (CI runs the suite both ways).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import real_file

from cananalyze.checks.gaps import grouped_gaps
from cananalyze.checks.rules.bootup import _SENT, _senders
from cananalyze.checks.rules.drive_fault import DriveFaultRule
from cananalyze.core.columns.order import stable_order
from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
)
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.nmt_state import NmtStates
from cananalyze.decode.node_load import NodeLoad
from cananalyze.decode.node_tally import NodeTally
from cananalyze.formats.source import read_all
from cananalyze.protocol.busload import bits_per_channel, frame_bits
from cananalyze.protocol.services import SERVICE_NAMES, Service
from cananalyze.runtime import speedups


@pytest.mark.parametrize("top", [1, 2, 97, 2048, 65536])
@pytest.mark.parametrize("n", [0, 1, 63, 64, 5000])
def test_stable_order_is_numpys_stable_argsort(n, top):
    rng = np.random.default_rng(n * 7 + top)
    keys = rng.integers(0, top, n)
    for k in (keys, keys.astype(np.uint16), keys.astype(np.uint32), np.sort(keys)):
        got = stable_order(k)
        assert got.dtype == np.intp
        np.testing.assert_array_equal(got, np.argsort(k, kind="stable"))
        if n:
            np.testing.assert_array_equal(stable_order(k, int(k.max())), got)


def test_stable_order_on_a_real_logs_identifiers():
    logs = (
        "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log",
        "jclinton830__canopen_test/candump.txt",
    )
    ids = np.concatenate([read_all(real_file(rel)).can_id for rel in logs])
    assert ids.size > 10000 and np.unique(ids).size > 8
    np.testing.assert_array_equal(stable_order(ids), np.argsort(ids, kind="stable"))


@pytest.mark.skipif(getattr(speedups.C, "stable_order", None) is None, reason="not built")
def test_compiled_stable_order_refuses_a_key_past_nkeys():
    order = np.empty(3, np.intp)
    with pytest.raises(ValueError, match="not below nkeys"):
        speedups.C.stable_order(np.array([1, 5, 2], np.uint16), 5, order)
    with pytest.raises(ValueError):
        speedups.C.stable_order(np.array([1], np.uint16), 0, np.empty(1, np.intp))
    with pytest.raises(ValueError):  # an order buffer too short
        speedups.C.stable_order(np.array([1, 2], np.uint16), 5, np.empty(1, np.intp))


@pytest.mark.parametrize("channels", [1, 3, 64, 65, 300])
def test_bits_per_channel_sums_frame_bits(channels):
    rng = np.random.default_rng(channels)
    n = 20000
    bits = (FLAG_EXT, FLAG_RTR, FLAG_ERR, FLAG_FD, FLAG_BRS, FLAG_TX)
    flags = np.zeros(n, np.uint8)
    for b in bits:
        flags |= np.where(rng.random(n) < 0.3, b, 0).astype(np.uint8)
    dlc = rng.integers(0, 65, n).astype(np.uint8)
    channel = rng.integers(0, channels, n).astype(np.uint16)
    frames, got = bits_per_channel(flags, dlc, channel)
    each = frame_bits(flags, dlc)
    np.testing.assert_array_equal(frames, np.bincount(channel))
    want = np.array([int(each[channel == c].sum()) for c in range(frames.size)])
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def test_senders_are_the_nodes_with_a_row_they_sent():
    rng = np.random.default_rng(5)
    for n in (0, 1, 1000):
        service = rng.integers(0, len(SERVICE_NAMES), n).astype(np.uint8)
        node = rng.integers(-1, 128, n).astype(np.int16)
        want = np.zeros(128, bool)
        want[node[_SENT[service] & (node >= 0)]] = True
        got = np.zeros(128, bool)
        batch = _batch(service, node)
        got[_senders(batch)] = True
        np.testing.assert_array_equal(got, want)
        # the same counts the node tally adds (one bincount, kept for both)
        assert batch.sender_counts() is batch.sender_counts()
        tally = NodeTally()
        tally.add(batch, [])
        per = np.zeros((128, len(SERVICE_NAMES)), np.int64)
        has = node >= 0
        np.add.at(per, (node[has], service[has]), 1)
        np.testing.assert_array_equal(tally.counts, per)


@pytest.mark.parametrize("shaped", [False, True])
def test_node_load_and_sender_counts_from_one_count_of_the_rows(shaped):
    """The node load's bits and the sender counts, read from one count per (service, node,
    length) (`DecodedBatch.sender_shapes`), are each frame's bits and each row summed per
    node; with a frame whose flags change its bits (29-bit, RTR, FD) or a length past 15,
    the rows are counted as before."""
    rng = np.random.default_rng(11)
    for n in (0, 1, 5000):
        service = rng.integers(0, len(SERVICE_NAMES), n).astype(np.uint8)
        node = rng.integers(-1, 128, n).astype(np.int16)
        batch = _batch(service, node)
        batch.frames.dlc[:] = rng.integers(0, 9, n)
        if shaped and n:
            batch.frames.flags[::7] = FLAG_EXT
            batch.frames.flags[::11] |= FLAG_RTR
        assert (batch.sender_shapes() is None) == (shaped and n > 0)
        load = NodeLoad()
        load.add(batch)
        sent = _SENT[service] & (node >= 0)
        bits = frame_bits(batch.frames.flags, batch.frames.dlc)
        want_frames = np.bincount(node[sent], minlength=128)
        want_bits = np.bincount(node[sent], weights=bits[sent], minlength=128).astype(np.int64)
        if n:
            [(frames, got_bits)] = load.sent.values()
            np.testing.assert_array_equal(frames, want_frames)
            np.testing.assert_array_equal(got_bits, want_bits)
        want = np.zeros((256, 129), np.int64)
        np.add.at(want, (service, node + 1), 1)
        got = batch.sender_counts()
        assert got.dtype == np.int64 and got.shape == (256, 129)
        np.testing.assert_array_equal(got, want)


def test_sender_counts_refuse_a_node_out_of_range():
    service = np.full(2, Service.HEARTBEAT, np.uint8)
    batch = _batch(service, np.array([3, 200], np.int16))
    assert batch.sender_counts() is None
    assert sorted(_senders(batch).tolist()) == [3, 200]  # read from the rows instead


def _batch(service: np.ndarray, node: np.ndarray) -> DecodedBatch:
    n = service.size
    fb = FrameBatch(
        t=np.arange(n, dtype=np.float64),
        can_id=np.zeros(n, np.uint32),
        flags=np.zeros(n, np.uint8),
        dlc=np.zeros(n, np.uint8),
        data=np.zeros((n, 8), np.uint8),
        channel=np.zeros(n, np.uint16),
        line=np.arange(1, n + 1, dtype=np.int64),
    )
    return DecodedBatch(fb, service, node, np.zeros(n, np.uint8))


def test_steady_state_agrees_with_state_at():
    rng = np.random.default_rng(9)
    nmt = NmtStates()
    t = 0.0
    for _ in range(40):
        t += float(rng.random())
        nmt._add(3, t, int(rng.choice([0, 4, 5, 127])), "nmt")
    times = np.asarray(nmt.times[3])
    probes = np.r_[times, times + 1e-9, times - 1e-9, -1.0, t + 5]
    for lo, hi in rng.choice(probes, (400, 2)):
        lo, hi = min(lo, hi), max(lo, hi)
        got = nmt.steady_state(3, lo, hi)
        inside = np.r_[lo, hi, probes[(probes >= lo) & (probes <= hi)]]
        states = np.unique(nmt.state_at(3, inside))
        if got is None:
            assert np.any((times > lo) & (times <= hi))
        else:
            assert states.tolist() == [got]
    assert nmt.steady_state(8, 0.0, 1.0) == -1  # a node with no state: unknown
    nmt._add(4, 2.0, 5, "nmt")
    nmt._add(4, 1.0, 4, "nmt")  # out of order (an unsorted log): no shortcut
    assert nmt.steady_state(4, 3.0, 4.0) is None


def test_last_emcy_per_node_as_columns_is_the_loop():
    rng = np.random.default_rng(3)
    n = 3000

    class Frames:
        t = np.cumsum(rng.random(n))

    rows = np.sort(rng.choice(n, 500, replace=False))
    nodes = rng.integers(1, 20, rows.size).astype(np.int16)
    codes = np.where(rng.random(rows.size) < 0.4, 0, rng.integers(1, 0x10000, rows.size))
    loop, cols = DriveFaultRule(), DriveFaultRule()
    for r, nd, c in zip(rows.tolist(), nodes.tolist(), codes.tolist(), strict=True):
        loop._saw(Frames, r, nd, c)
    cols._saw_last(Frames, rows, nodes, codes)
    assert cols.emcy == loop.emcy and len(loop.emcy) > 5
    cols._saw_last(Frames, rows[:0], nodes[:0], codes[:0])
    assert cols.emcy == loop.emcy


def _gaps_one_by_one(t, keys, rows, last):
    """What grouped_gaps promises, a frame at a time (no sort, no gather): the frames of
    each key, keys ascending, in row order within a key; each frame's previous time is
    the previous frame of its key, the first one's the time carried in `last`."""
    by_key: dict[int, list[int]] = {}
    for row, key in zip(rows.tolist(), keys.tolist(), strict=True):
        by_key.setdefault(int(key), []).append(row)
    k, tt, prev, r, starts = [], [], [], [], []
    for key in sorted(by_key):
        starts.append(len(k))
        for row in by_key[key]:
            k.append(key)
            tt.append(float(t[row]))
            prev.append(float(last[key]))
            r.append(row)
            last[key] = t[row]
    return (
        np.array(k, np.intp),
        np.array(tt, np.float64),
        np.array(prev, np.float64),
        np.array(r, rows.dtype),
        np.array(starts, np.intp),
    )


def test_grouped_gaps_are_the_sorted_gaps_carried_across_batches():
    rng = np.random.default_rng(11)
    for size in (1, 128, 2048):
        mine, ref = np.full(size, np.nan), np.full(size, np.nan)
        for n in (0, 5, 64, 3000, 3000):  # batches after one another: `last` carries
            t = np.cumsum(rng.random(n))
            rows = np.sort(rng.choice(n, n // 2, replace=False)) if n else np.zeros(0, np.intp)
            for dtype in (np.intp, np.uint32, np.int16):
                keys = rng.integers(0, size, rows.size).astype(dtype)
                got = grouped_gaps(t, keys, rows, mine)
                want = _gaps_one_by_one(t, keys, rows, ref)
                for col, w in zip(("key", "t", "prev", "row", "starts"), want, strict=True):
                    g = getattr(got, col)
                    assert g.dtype == w.dtype, col
                    np.testing.assert_array_equal(g, w)
                np.testing.assert_array_equal(mine, ref)
        assert np.isfinite(mine).sum() > min(size, 1000) // 2


@pytest.mark.skipif(getattr(speedups.C, "group_gaps", None) is None, reason="not built")
def test_compiled_group_gaps_refuses_rows_and_keys_out_of_range():
    def call(keys, rows, nt=10, nlast=4):
        n = len(keys)
        return speedups.C.group_gaps(
            np.array(keys, np.uint16), np.array(rows, np.intp), np.zeros(nt), np.zeros(nlast),
            np.empty(n, np.intp), np.empty(n), np.empty(n), np.empty(n, np.intp),
            np.empty(nlast, np.intp),
        )  # fmt: skip

    assert call([3, 0, 3], [1, 2, 9]) == 2
    with pytest.raises(ValueError, match="out of range"):
        call([4], [1])
    with pytest.raises(ValueError, match="out of range"):
        call([1], [10])
    with pytest.raises(ValueError, match="out of range"):
        call([1], [-1])
