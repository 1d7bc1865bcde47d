"""Bulk-parsed timestamps (candump, ASC) equal float(text) exactly, for any digit counts."""

from __future__ import annotations

import random

from readers_util import run

from cananalyze.formats.logs import asc, candump


def _times(seed: int, n: int = 3000) -> list[str]:
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        ni, nf = rng.randint(1, 11), rng.choice([0, 1, 3, 6, 6, 6, 9, 12])
        whole = str(rng.randrange(10**ni)).zfill(ni if rng.random() < 0.3 else 1)
        out.append(whole + ("." + str(rng.randrange(10**nf)).zfill(nf) if nf else ""))
    return out


def test_candump_times_are_exact() -> None:
    for seed in range(3):
        times = _times(seed)
        text = "".join(f"({t}) can0 181#00\n" for t in times).encode()
        batch, ctx, _ = run(candump.read, text, batch_size=10**6)
        assert ctx.problems.count == 0
        assert batch.t.tolist() == [float(t) for t in times]


def test_asc_times_are_exact() -> None:
    times = [t for t in _times(7) if "." in t]
    text = "base hex  timestamps absolute\n" + "".join(f"{t} 1  181  Rx   d 1 00\n" for t in times)
    batch, ctx, _ = run(asc.read, text.encode())
    assert ctx.problems.count == 0
    assert batch.t.tolist() == [float(t) for t in times]
