"""The two spools that keep an export's memory flat in log length: the findings, on disk
until the table is written by time (outputs/tables/findings_spool.py), and the heartbeat
gaps a learned period is judged from (checks/spool.py).

Each run with the spool's block size cut to a few rows (every path through the disk)
gives what the same run gives with the defaults, on the generator's faulty bus, where
findings come from every path: columns, rows emitted alone (with their Finding) and
learned heartbeat periods. The findings table is read back with pyarrow and compared
with `cananalyze.check`'s findings, in order."""

from __future__ import annotations

import copy
import math

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import generated_log

import cananalyze
from cananalyze.checks import spool
from cananalyze.checks.spool import KeyedSpool
from cananalyze.outputs.tables import findings_spool
from cananalyze.outputs.tables.stream import TableSink
from cananalyze.pipeline import Options, build_checker, build_decoder, open_source, run


@pytest.fixture(scope="module")
def faults(tmp_path_factory):
    return generated_log(tmp_path_factory.mktemp("faults"), 60_000)


def test_keyed_spool_gives_each_key_back_in_the_order_added(monkeypatch):
    monkeypatch.setattr(spool, "FLUSH", 5)
    rng = np.random.default_rng(7)
    s, want = KeyedSpool(2), {}
    for _ in range(300):
        key, n = int(rng.integers(0, 4)), int(rng.integers(0, 9))
        a, b = rng.random(n), rng.random(n)
        s.add(key, a, b)
        if n:
            want.setdefault(key, []).append((a.copy(), b.copy()))
        a[:] = -1  # the caller's arrays change after: the spool kept its own copy
    assert s._file is not None  # most rows went through the file
    assert sorted(s.keys()) == sorted(want)
    twin = copy.deepcopy(s)
    for key, parts in want.items():
        for got in (s.get(key), twin.get(key)):
            np.testing.assert_array_equal(got[0], np.concatenate([p[0] for p in parts]))
            np.testing.assert_array_equal(got[1], np.concatenate([p[1] for p in parts]))
    assert 9 not in s
    assert [c.size for c in s.get(9)] == [0, 0]


def _key(f) -> tuple:
    return (f.t, f.rule, f.node, f.message, str(f.measured), str(f.expected))


def test_learned_heartbeat_periods_judged_from_the_spooled_gaps(monkeypatch, faults):
    whole = cananalyze.check(str(faults))
    learned = [f for f in whole if "period learned" in f.message]
    assert len(learned) > 10  # the path under test: 0x1017 not known, the median learned
    monkeypatch.setattr(spool, "FLUSH", 3)
    spooled = cananalyze.check(str(faults))
    assert [_key(f) for f in spooled] == [_key(f) for f in whole]


def _export(log, out) -> None:
    opts = Options(checks=True)
    checker = build_checker(opts, keep_findings=False)  # as export: the sink's own copy only
    run(
        open_source(str(log), opts), build_decoder(opts, checker), [TableSink(out, "parquet")], opts
    )


def test_findings_table_read_back_from_the_spool_by_time(monkeypatch, tmp_path, faults):
    _export(faults, tmp_path / "whole")
    monkeypatch.setattr(findings_spool, "BLOCK", 7)
    monkeypatch.setattr(findings_spool, "CACHED", 2)  # a late finding's block read again
    _export(faults, tmp_path / "spooled")
    whole = pq.read_table(tmp_path / "whole" / "findings.parquet")
    spooled = pq.read_table(tmp_path / "spooled" / "findings.parquet")
    assert spooled.equals(whole)
    checked = cananalyze.check(str(faults))
    assert spooled.num_rows == len(checked) > 1000
    t = spooled.column("t").to_pylist()
    assert t == sorted(t)
    rules, messages = spooled.column("rule").to_pylist(), spooled.column("message").to_pylist()
    rows = zip(t, rules, messages, strict=True)
    for (t_row, rule, message), f in zip(rows, checked, strict=True):
        assert (rule, message) == (f.rule, f.message)
        assert math.isclose(t_row, f.t, abs_tol=1e-9)
    alone = [f for f in checked if f.rule == "heartbeat" and "dropout" in f.message]
    assert alone  # rows emitted alone (their Finding kept in memory) are among them


def test_keyed_spool_without_a_temporary_directory_keeps_the_values(monkeypatch):
    def refuse(*args, **kwargs):
        raise PermissionError("read-only")

    monkeypatch.setattr(spool, "FLUSH", 2)
    monkeypatch.setattr(spool.tempfile, "TemporaryFile", refuse)
    s = KeyedSpool(1)
    for k in range(5):
        s.add(3, np.arange(k, k + 3, dtype=float))
    assert s._file is None
    np.testing.assert_array_equal(
        s.get(3)[0], np.concatenate([np.arange(k, k + 3) for k in range(5)])
    )


def test_keyed_spool_keeps_the_values_when_the_disk_fills_up(monkeypatch):
    """A temporary directory that fills up mid-log (a small /tmp): what was written is
    read back, what could not be stays in memory, and nothing is lost or doubled."""
    monkeypatch.setattr(spool, "FLUSH", 4)
    real = spool.tempfile.TemporaryFile

    class Full:
        """The real unbuffered file, whose writes fail past `room` bytes, partway through
        a write (the first bytes go in, then ENOSPC) and with short writes before that."""

        def __init__(self, *args, **kwargs):
            self.f, self.room = real(*args, **kwargs), 200

        def write(self, data):
            data = memoryview(data)[:24]  # at most 24 bytes a call: short writes
            if self.f.tell() + len(data) > self.room:
                self.f.write(data[:8])
                raise OSError(28, "No space left on device")
            return self.f.write(data)

        def __getattr__(self, name):
            return getattr(self.f, name)

    monkeypatch.setattr(spool.tempfile, "TemporaryFile", Full)
    s, want = KeyedSpool(2), {0: [], 1: []}
    for k in range(40):
        key, a = k % 2, np.arange(k, k + 3, dtype=float)
        s.add(key, a, -a)
        want[key].append(a)
    assert s._records[0] and not s._disk  # some rows went to the file before it filled
    for key, parts in want.items():
        got = s.get(key)
        np.testing.assert_array_equal(got[0], np.concatenate(parts))
        np.testing.assert_array_equal(got[1], -np.concatenate(parts))
