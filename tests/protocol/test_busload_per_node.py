"""`bits_per_node` (one bincount of every row, a fast path for classic standard frames)
against the frame-by-frame sum of `frame_bits` over the rows each node sent, on random
batches: classic, extended, remote, error and FD frames, rows of no node and a node-ID
out of range."""

from __future__ import annotations

import numpy as np
import pytest

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX
from cananalyze.protocol.busload import bits_per_node, frame_bits

FLAGS = np.array([0, FLAG_EXT, FLAG_RTR, FLAG_ERR, FLAG_FD, FLAG_TX, FLAG_EXT | FLAG_FD], np.uint8)


@pytest.mark.parametrize("seed", range(40))
def test_bits_per_node_is_the_sum_of_each_frames_bits(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 3000))
    node = rng.integers(-1, 128, n).astype(np.int16)
    if seed % 5 == 0 and n:
        node[rng.integers(0, n)] = 300  # not a node-ID: not counted
    classic = seed % 2 == 0
    flags = np.zeros(n, np.uint8) if classic else rng.choice(FLAGS, n)
    dlc = rng.integers(0, 9 if seed % 3 else 65, n).astype(np.uint8)
    sent = rng.random(n) < 0.6
    frames, bits = bits_per_node(flags, dlc, node, sent)
    keep = sent & (node >= 0) & (node < 128)
    by_frame = [0] * 128
    for k in np.flatnonzero(keep).tolist():
        by_frame[node[k]] += int(frame_bits(flags[k : k + 1], dlc[k : k + 1])[0])
    assert bits.tolist() == by_frame
    assert frames.tolist() == np.bincount(node[keep], minlength=128).tolist()
    assert frames.dtype == bits.dtype == np.int64 and len(frames) == len(bits) == 128


def test_no_rows():
    empty = np.zeros(0, np.uint8)
    frames, bits = bits_per_node(empty, empty, np.zeros(0, np.int16), np.zeros(0, bool))
    assert frames.tolist() == bits.tolist() == [0] * 128
