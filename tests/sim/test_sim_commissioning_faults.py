"""The `commissioning-faults` scenario: each injected fault is found by its own analysis,
with the right node and step, and the healthy `commissioning` scenario gives none of them.

The log is read back with python-can (the frames the faults put on the bus: LSS, SYNC
times, the two producers of one COB-ID) and through `cananalyze.load` with the samples'
network file, which declares each node's device (the identity the boot is checked against).
"""

from __future__ import annotations

import re

import can
import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLES

import cananalyze
from cananalyze.cli.main import main
from cananalyze.formats.logfile import write_log
from cananalyze.sim.engine import START
from cananalyze.sim.scenarios import JITTER, LSS_SERIAL, SYNC_PERIOD
from cananalyze.sim.session import simulate

NETWORK = SAMPLES / "network.toml"
DURATION = 10.0
LSS_NODE = 10  # the first node-ID free on the samples' network (3, 5, 6, 7)


def _run(tmp_path_factory, scenario: str):
    path = tmp_path_factory.mktemp(scenario) / f"{scenario}.log"
    write_log(simulate(scenario=scenario, duration=DURATION, seed=0), path)
    return path, cananalyze.load(path, network=NETWORK)


@pytest.fixture(scope="module")
def faulty(tmp_path_factory):
    return _run(tmp_path_factory, "commissioning-faults")


@pytest.fixture(scope="module")
def healthy(tmp_path_factory):
    return _run(tmp_path_factory, "commissioning")


def _messages(path) -> list[can.Message]:
    with can.LogReader(str(path)) as reader:
        return list(reader)


def _stories(cap) -> dict:
    return {int(r.node): r for r in cap.boot.itertuples()}


def test_the_scenario_is_deterministic_per_seed():
    a = simulate(scenario="commissioning-faults", duration=3.0, seed=1)
    b = simulate(scenario="commissioning-faults", duration=3.0, seed=1)
    c = simulate(scenario="commissioning-faults", duration=3.0, seed=2)
    assert np.array_equal(a.t, b.t) and np.array_equal(a.data, b.data)
    assert not np.array_equal(a.t[: len(c)], c.t[: len(a)])


def test_boot_stops_at_identity_configuration_and_nmt_start(faulty):
    _, cap = faulty
    s = _stories(cap)
    assert (s[5].result, s[5].stopped_at, s[5].status) == ("stopped", "identity", "M")
    assert "product code 0x3, expected 0x2" in s[5].verdict
    assert (s[6].result, s[6].stopped_at, s[6].status) == ("stopped", "configuration", "J")
    assert "0x1801:02 aborted 0x06090030" in s[6].verdict
    assert (s[7].result, s[7].stopped_at) == ("stopped", "NMT start")
    assert pd.isna(s[7].status) and "error control: guarding" in s[7].steps
    assert s[3].result == s[LSS_NODE].result == "operational"
    boot = cap.findings[cap.findings.rule == "boot"]
    assert sorted(boot.node.tolist()) == [5, 6, 7]


def test_lss_gives_the_identity_its_node_id(faulty):
    path, cap = faulty
    a = cap.lss_assignments
    assert len(a) == 1
    row = a.iloc[0]
    assert (row.vendor_id, row.product_code, row.revision, row.serial) == (0x3CD, 2, 0, LSS_SERIAL)
    assert (row.node_id, bool(row.stored)) == (LSS_NODE, True)
    msgs = _messages(path)
    answers = [m for m in msgs if m.arbitration_id == 0x7E4]
    assert [m.data[0] for m in answers] == [0x44, 0x11, 0x17]  # selected, node-ID ok, stored
    assert all(m.data[1] == 0 for m in answers[1:])
    boot = next(m for m in msgs if m.arbitration_id == 0x700 + LSS_NODE)
    assert boot.data[0] == 0 and boot.timestamp > answers[-1].timestamp


def test_sync_jitter_is_found_only_in_its_window(faulty):
    path, cap = faulty
    msgs = _messages(path)
    sync = np.array([m.timestamp - START for m in msgs if m.arbitration_id == 0x080])
    gap, end = np.diff(sync), sync[1:]  # each gap by the SYNC that ends it, simulated s
    inside = (end > JITTER[0]) & (end < JITTER[1] + SYNC_PERIOD)
    assert np.abs(gap[inside] - SYNC_PERIOD).max() > 0.02  # up to +-30 ms each end
    assert np.abs(gap[~inside] - SYNC_PERIOD).max() < 0.001
    found = cap.findings[cap.findings.rule == "sync"]
    assert len(found) >= 5
    assert found.node.isna().all() and (found.cob_id == 0x080).all()
    assert (found.t - START).between(JITTER[0], JITTER[1] + SYNC_PERIOD).all()
    # the PDOs follow each SYNC at once: inside the window 0x1007 written (20 ms)
    assert cap.findings[cap.findings.rule == "pdo_sync"].empty


def _sync_jitter_ms(path, capsys) -> float:
    """`check --timing`'s SYNC period jitter (its standard deviation, ms)."""
    capsys.readouterr()
    main(["check", str(path), "--network", str(NETWORK), "--timing", "--no-color"])
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("SYNC period:"))
    return float(re.search(r"jitter ([0-9.]+) ms", line).group(1))


def test_the_timing_shows_the_sync_jitter(faulty, healthy, capsys):
    assert _sync_jitter_ms(faulty[0], capsys) > 5.0  # +-30 ms for 2 of the 10 s
    assert _sync_jitter_ms(healthy[0], capsys) < 0.1  # a SYNC waiting for a busy bus


def test_consistency_names_the_cob_id_collision(faulty):
    path, cap = faulty
    found = cap.findings[cap.findings.rule == "consistency"]
    assert len(found) == 1
    row = found.iloc[0]
    assert (row.node, row.cob_id) == (LSS_NODE, 0x283)
    assert "node 3's TPDO2" in row.message and f"node {LSS_NODE}'s TPDO2" in row.message
    # on the wire: the MCB-560's 8-byte analog TPDO2 and the DAT 7014's 4-byte one
    lengths = {m.dlc for m in _messages(path) if m.arbitration_id == 0x283}
    assert lengths == {4, 8}


def test_the_healthy_commissioning_has_none_of_these(healthy):
    _, cap = healthy
    assert set(cap.boot.result) == {"operational"} and cap.boot.status.isna().all()
    rules = set(cap.findings.rule)
    assert not rules & {"boot", "consistency", "sync", "pdo_sync", "lss", "sdo"}
    assert cap.lss.empty and cap.lss_assignments.empty
