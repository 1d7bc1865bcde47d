"""The columnar SDO aggregates give what reading every record dict gives.

Summary, timing statistics, the SDO rule and the network model read the fast
path's transactions from columns (`SdoRecords.cols`, `table()`: the record dicts
are built only when read). Each log is decoded twice through the whole `check`
pipeline, once with the fast path and once with every frame through the tracker
(plain dicts, no columns): summary lines, timing report, findings, the model's
configuration history and every record must be the same.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SAMPLES, real_file

from cananalyze.checks.build import build_checker
from cananalyze.core.frames import FrameBatch
from cananalyze.formats.source import read_all
from cananalyze.outputs.summary import Summary, device_lines
from cananalyze.pipeline import Options, build_decoder

sys.path.insert(0, str(ROOT / "benchmarks"))


def _check(
    fb: FrameBatch, fast: bool, step: int, devices: int = 0, network=None, rules=None
) -> dict:
    checker = build_checker(rules)
    opts = Options(network=network, devices={k: "dat7014" for k in range(1, devices + 1)})
    decoder = build_decoder(opts, checker)
    decoder.processors[0].fast = fast
    summary = Summary()
    tables = []
    records = []
    for start in range(0, len(fb), step):
        batch = decoder.decode(fb.take(slice(start, start + step)))
        summary.add(batch)
        tab = batch.records.table()
        tables.append(
            (
                [tab.node_keys[c] for c in tab.node.tolist()],
                [tab.result_keys[c] for c in tab.result.tolist()],
                np.nan_to_num(tab.latency, nan=-1.0).tolist(),
            )
        )
        records += [(start + row, rec) for row, rec in batch.records]
    tail = decoder.finish()
    summary.add(tail)
    model = decoder.network
    return {
        "summary": summary.lines(bitrate=500_000) + device_lines(model, summary),
        "sdo_results": summary.sdo_results,
        "report": repr(checker.report()),
        "timing": checker.timing.lines(checker.nmt),
        "findings": [f.record() for f in checker.findings],
        "subjects": [sorted(map(str, r.subjects)) for r in checker.rules],
        "history": list(model.history),
        "nodes": {
            n: (c.identified_by, c.profile and c.profile.key) for n, c in model.nodes.items()
        },
        "tables": tables,
        "records": records + [rec for _, rec in tail.records],
    }


def assert_same(fb: FrameBatch, steps=(1 << 20, 4096), **kw) -> None:
    for step in steps:
        fast, slow = _check(fb, True, step, **kw), _check(fb, False, step, **kw)
        for key in fast:
            if key == "tables":
                continue  # the slow path's table is read from dicts: compared below per batch
            assert fast[key] == slow[key], f"{key} differs (batch size {step})"
            if key in ("sdo_results", "nodes"):
                assert list(fast[key]) == list(slow[key]), f"{key} order (batch size {step})"
        assert fast["tables"] == slow["tables"], f"SDO tables differ (batch size {step})"


def test_benchmark_mix_with_devices() -> None:
    from generate import generate

    assert_same(generate(120_000), devices=16)


def test_benchmark_mix_slow_replies_flagged(tmp_path: Path) -> None:
    """A latency limit flags fast-path records: the SDO rule builds those (then all)."""
    from generate import generate

    for limit in (0.39, 0.1):  # a few slow replies per batch / most of them
        rules = tmp_path / f"rules{limit}.yaml"
        rules.write_text(f"assert:\n  - sdo: {{max_latency_ms: {limit}}}\n")
        assert_same(generate(40_000), steps=(1 << 20, 5000), rules=str(rules))


def test_benchmark_mix_without_devices() -> None:
    from generate import generate

    assert_same(generate(60_000), steps=(1 << 20, 999))


@pytest.mark.parametrize("name", ["demo.log", "faults.log", "commissioning.log"])
def test_samples(name: str) -> None:
    path = SAMPLES / name
    if not path.exists():
        pytest.skip(f"no {name}")
    assert_same(read_all(path), network=str(SAMPLES / "network.toml"))
    assert_same(read_all(path), rules=str(SAMPLES / "rules.yaml"))


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan2.trc",
        "isPointless__Sevcon/can_180209_154604.txt",
        "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
        "SeonilChoi__CANOPEN-SDK/log.txt",
    ],
)
def test_real_logs(rel: str) -> None:
    assert_same(read_all(real_file(rel)), steps=(1 << 20, 777))
