"""The non-PEAK CarBusAnalyzer.trc from SavvyCAN's examples."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import real_file
from readers_util import run

from cananalyze.formats.logs import canbusanalyzer, trc

FILE = "collin80__SavvyCAN/CarBusAnalyzer.trc"


def test_reads_all_declared_frames():
    path = real_file(FILE)
    batch, ctx, _ = run(canbusanalyzer.read, path, batch_size=20)
    assert len(batch) == 55 and ctx.problems.count == 0  # header: "@ 55 @"
    assert batch.can_id[:2].tolist() == [0x45A, 0x4E0]
    assert batch.payload(0) == bytes.fromhex("5A04000000000000")
    assert batch.t[0] == pytest.approx(46.016)
    assert batch.t[-1] - batch.t[0] == pytest.approx(10.078)  # header: "00:00:10.078"
    assert np.all(np.diff(batch.line) == 1) and batch.line[0] == 2
    assert canbusanalyzer.sniff(path.read_bytes()) and not trc.sniff(path.read_bytes())


def test_bad_row_and_count_mismatch():
    text = b"@ TEXT @ 2 @ 64 @ 0 @ 3 @ 10 @ 00:00:00.010 @\r1,0\t1\t0004\t12G\t1\t00\t0\tx\t\r1,5\t1\t0004\t123\t2\t01 02\t0\tx\t\r"
    batch, ctx, _ = run(canbusanalyzer.read, text, source="c.trc")
    assert batch.can_id.tolist() == [0x123] and batch.t.tolist() == [1.5]
    assert [str(p) for p in ctx.problems.shown] == [
        "c.trc:line 2: invalid identifier '12G'",
        "c.trc:line 1: header says 3 frames, file has 2",
    ]
