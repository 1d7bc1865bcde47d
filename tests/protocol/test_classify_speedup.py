"""The compiled classifier (`_speedups.classify`) gives exactly the numpy classifier's columns.

CI runs the suite without the helper too, where the true-value tests (test_classify_real,
test_manual_frames, test_identifier_range) check the numpy path; this file checks
that the two agree on inputs no real log has (every flag, RTR/answer sequences cut
at batch edges, remapped tables).

Both run over the same batches with their own CobClassifier, so the error-control
state carried between batches (last frame per COB-ID an RTR) is compared too:
real traces with node guarding, the samples, and seeded random frames with every
flag combination, RTR/answer sequences cut at batch edges and remapped tables.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import real_file

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR, FLAG_TX, FrameBatch
from cananalyze.formats.source import read_all
from cananalyze.protocol.cobid import CobClassifier
from cananalyze.protocol.services import Service
from cananalyze.runtime import speedups

pytestmark = pytest.mark.skipif(
    getattr(speedups.C, "classify", None) is None, reason="compiled helper not built"
)
SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def _cut(batch: FrameBatch, size: int) -> list[FrameBatch]:
    return [batch.take(np.arange(i, min(i + size, len(batch)))) for i in range(0, len(batch), size)]


def _same(batches: list[FrameBatch], edit=None) -> int:
    """Classify with both paths (fresh classifiers, `edit` applied to each); frames compared."""
    compiled, numpy_only = CobClassifier(), CobClassifier()
    if edit:
        edit(compiled)
        edit(numpy_only)
    n = 0
    for b in batches:
        got = compiled.classify(b)
        ref = numpy_only._classify_numpy(b)
        for col in ("service", "node", "pdo"):
            a, r = getattr(got, col), getattr(ref, col)
            assert a.dtype == r.dtype, col
            bad = np.flatnonzero(a != r)
            assert bad.size == 0, f"{col} differs at rows {bad[:5].tolist()}"
        assert (compiled._prev_rtr == numpy_only._prev_rtr).all()
        n += len(b)
    return n


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan1.trc",
        "hilch__canopen-message-interpreter/pcan2.trc",
        "hilch__canopen-message-interpreter/ixxat1.trc",
    ],
)
def test_real_traces(rel):
    batch = read_all(real_file(rel))
    assert _same(_cut(batch, 97)) == len(batch)
    assert _same([batch]) == len(batch)


@pytest.mark.parametrize("name", ["demo.log", "demo.asc"])
def test_samples(name):
    batch = read_all(SAMPLES / name)
    assert _same(_cut(batch, 50)) == len(batch) > 0


def _random(seed: int, n: int) -> FrameBatch:
    rng = np.random.default_rng(seed)
    b = FrameBatch.allocate(n, ("can0",))
    b.t[:] = np.arange(n) / 1000.0
    # mostly error control of a few nodes (RTR requests, answers, boot-ups), plus everything else
    ec = 0x700 + rng.integers(1, 4, n)
    anything = rng.integers(0, 4096, n)  # also "standard" ids above 0x7FF: never CANopen
    b.can_id[:] = np.where(rng.random(n) < 0.6, ec, anything).astype(np.uint32)
    flag_bits = np.array([0, 0, 0, FLAG_RTR, FLAG_EXT, FLAG_ERR, FLAG_TX, FLAG_RTR | FLAG_EXT])
    b.flags[:] = rng.choice(flag_bits, n).astype(np.uint8)
    b.dlc[:] = rng.integers(0, 9, n).astype(np.uint8)
    b.data[:] = rng.choice(np.array([0x00, 0x05, 0x7F, 0x80, 0x85, 0xFF], np.uint8), (n, 8))
    return b


@pytest.mark.parametrize("seed", range(6))
def test_random_frames_across_batches(seed):
    batch = _random(seed, 5000)
    assert _same(_cut(batch, 1 + seed * 37)) == 5000
    services = CobClassifier().classify(batch).service
    # the traffic covers every error-control reading
    for s in (Service.HEARTBEAT, Service.BOOTUP, Service.GUARD_REQUEST, Service.GUARD_RESPONSE):
        assert (services == s).any(), s
    assert (services == Service.ERRCTL_INVALID).any()  # data frames of 0, 2..8 bytes


def test_wrong_length_frames_between_request_and_answer():
    """RTR, frames of every other length, then the 1-byte answer, on three COB-IDs,
    cut at every batch size: both paths keep the RTR state across the invalid frames."""
    rows = []
    for k in range(40):
        cob = 0x701 + k % 3
        rows.append((cob, FLAG_RTR, 1, 0))
        rows += [(cob, 0, n, 0x05) for n in (0, 2, 8)[: k % 4]]
        rows.append((cob, 0, 1, 0x85 if k % 2 else 0x05))
    n = len(rows)
    b = FrameBatch.allocate(n, ("can0",))
    b.t[:] = np.arange(n) / 1000.0
    b.can_id[:] = [r[0] for r in rows]
    b.flags[:] = [r[1] for r in rows]
    b.dlc[:] = [r[2] for r in rows]
    b.data[:, 0] = [r[3] for r in rows]
    for size in (1, 2, 3, 7, n):
        assert _same(_cut(b, size)) == n
    services = CobClassifier().classify(b).service
    assert (services == Service.GUARD_RESPONSE).sum() == 40
    assert (services == Service.ERRCTL_INVALID).sum() == sum(min(k % 4, 3) for k in range(40))


def test_remapped_tables():
    def edit(c: CobClassifier) -> None:
        c.assign(0x1A5, Service.HEARTBEAT, 5)  # error control moved
        c.assign(0x190, Service.TPDO, 9, 2)
        c.release(0x701)

    batch = _random(11, 4000)
    batch.can_id[::3] = 0x1A5
    batch.can_id[1::7] = 0x190
    assert _same(_cut(batch, 333), edit) == 4000


def test_non_contiguous_and_empty_batches():
    batch = _random(3, 1000)
    view = FrameBatch(
        batch.t[::2],
        batch.can_id[::2],
        batch.flags[::2],
        batch.dlc[::2],
        batch.data[::2],
        batch.channel[::2],
        batch.line[::2],
    )
    assert _same([view, FrameBatch.empty()]) == 500
