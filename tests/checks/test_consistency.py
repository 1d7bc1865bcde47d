"""The `consistency` rule: a configuration that contradicts itself, told once, when it began."""

from __future__ import annotations

import tempfile
from pathlib import Path

import yaml

from cananalyze.checks.engine import Checker
from cananalyze.checks.rules.consistency import ConsistencyRule
from cananalyze.core.frames import from_rows
from cananalyze.pipeline import Options, build_decoder


def run(rows, network=None):
    """Decode rows through the pipeline's decoder and a Checker of the consistency rule."""
    checker = Checker([ConsistencyRule()])
    with tempfile.TemporaryDirectory() as tmp:
        net = Path(tmp) / "net.yaml"
        net.write_text(yaml.safe_dump(network or {}))
        dec = build_decoder(Options(network=net), checker)
    dec.decode(from_rows(sorted(rows, key=lambda r: r[0])))
    dec.finish()
    return [f for f in checker.findings if f.rule == "consistency"]


def write(t: float, node: int, index: int, sub: int, value: int, size: int = 4):
    """An expedited SDO download and its confirmation, as a master and node `node` send them."""
    cmd = {1: 0x2F, 2: 0x2B, 4: 0x23}[size]
    head = bytes([index & 0xFF, index >> 8, sub])
    return [
        (t, 0x600 + node, bytes([cmd]) + head + value.to_bytes(4, "little")),
        (t + 0.001, 0x580 + node, bytes([0x60]) + head + bytes(4)),
    ]


def heartbeats(nodes, until: float, period: float = 0.1):
    n = int(until / period)
    return [(i * period, 0x700 + node, b"\x05") for node in nodes for i in range(n + 1)]


def test_two_tpdos_on_one_cob_id_found_once_with_their_origins_and_ended():
    rows = heartbeats([5, 6], 6.0)
    rows += write(1.0, 5, 0x1800, 1, 0x190)  # node 5 TPDO1 on 0x190
    rows += write(2.0, 6, 0x1801, 1, 0x190)  # node 6 TPDO2 on 0x190 too
    rows += [(2.5 + i * 0.01, 0x190, b"\x01\x02") for i in range(50)]  # many frames: one finding
    rows += write(4.0, 6, 0x1801, 1, 0x80000190)  # node 6's made not valid: resolved
    (f,) = run(rows)
    assert f.severity == "error"
    assert f.cob_id == 0x190 and f.node == 6  # node 6's value came last
    assert abs(f.t - 2.001) < 1e-6  # when the second value took effect (its confirmation)
    assert "node 5's TPDO1" in f.message and "node 6's TPDO2" in f.message
    assert "0x1800:1 written at +1.001 s" in f.basis
    assert "0x1801:1 written at +2.001 s" in f.basis


def test_a_resolved_collision_that_comes_back_is_told_again():
    rows = heartbeats([5, 6], 8.0)
    rows += write(1.0, 5, 0x1800, 1, 0x190)
    rows += write(2.0, 6, 0x1800, 1, 0x190)
    rows += write(3.0, 6, 0x1800, 1, 0x191)  # resolved
    rows += write(5.0, 6, 0x1800, 1, 0x190)  # back
    found = run(rows)
    assert [round(f.t, 3) for f in found] == [2.001, 5.001]


def test_distinct_cob_ids_and_a_tpdo_with_its_rpdo_are_consistent():
    rows = heartbeats([5, 6], 4.0)
    rows += write(1.0, 5, 0x1800, 1, 0x190)
    rows += write(1.1, 6, 0x1800, 1, 0x191)
    rows += write(1.2, 6, 0x1400, 1, 0x190)  # node 6 consumes node 5's TPDO1: fine
    rows += write(1.3, 6, 0x1801, 1, 0x80000190)  # a not valid TPDO on it: no producer
    assert run(rows) == []


def test_emcy_cob_id_on_another_nodes_emcy_and_on_an_rpdo():
    rows = heartbeats([5, 6, 7], 4.0)
    rows += write(0.5, 5, 0x1014, 0, 0x85)
    rows += write(1.0, 6, 0x1014, 0, 0x85)  # node 6's EMCY on node 5's
    rows += write(2.0, 7, 0x1400, 1, 0x86)  # node 7's RPDO1 on node 6's old EMCY: not a clash
    found = run(rows)
    (f,) = found
    assert f.cob_id == 0x85 and f.severity == "error" and f.node == 6
    assert "node 5's EMCY" in f.message and "node 6's EMCY" in f.message
    assert f.basis == "0x1014 written at +0.501 s; 0x1014 written at +1.001 s"
    rows += write(3.0, 7, 0x1401, 1, 0x85)  # an RPDO on the EMCY COB-ID: takes EMCY as data
    found = run(rows)
    assert len(found) == 2
    assert "node 7's RPDO2" in found[1].message and found[1].severity == "error"


def test_heartbeat_consumer_time_not_longer_than_the_producer_time():
    rows = heartbeats([5, 6], 6.0)
    rows += write(1.0, 5, 0x1017, 0, 100, 2)
    rows += write(2.0, 6, 0x1016, 1, (5 << 16) | 105)  # 105 < 100 + 10 %: a finding
    rows += write(3.0, 6, 0x1016, 1, (5 << 16) | 250)  # resolved
    (f,) = run(rows)
    assert f.severity == "warning" and f.node == 6 and f.cob_id == 0x705
    assert abs(f.t - 2.001) < 1e-6
    assert f.measured == 105 and f.expected == 110
    assert "0x1016:1 written at +2.001 s" in f.basis and "0x1017 written at +1.001 s" in f.basis


def test_heartbeat_consumer_time_with_a_margin_is_consistent():
    rows = heartbeats([5, 6], 4.0)
    rows += write(1.0, 5, 0x1017, 0, 100, 2)
    rows += write(2.0, 6, 0x1016, 1, (5 << 16) | 150)
    assert run(rows) == []


def test_a_consumer_watching_a_node_that_never_sends_a_heartbeat_is_told_at_the_end():
    rows = heartbeats([6], 6.0)
    rows += write(1.0, 6, 0x1016, 1, (9 << 16) | 500)  # node 9 is never heard
    (f,) = run(rows)
    assert f.severity == "warning" and f.node == 6 and f.cob_id == 0x709
    assert f.at_end and abs(f.t - 1.001) < 1e-6
    assert "node 9 sent no heartbeat in the whole log" in f.message


def test_a_silent_producer_is_not_judged_before_three_consumer_times():
    rows = heartbeats([6], 2.0)
    rows += write(1.0, 6, 0x1016, 1, (9 << 16) | 500)  # 1 s of traffic after: too short
    assert run(rows) == []


def test_two_sync_producers_and_two_time_producers():
    rows = heartbeats([1, 2], 5.0)
    rows += write(1.0, 1, 0x1005, 0, 0x40000080)
    rows += write(2.0, 2, 0x1005, 0, 0x40000080)  # a second SYNC producer
    rows += write(3.0, 2, 0x1005, 0, 0x80)  # consumer again: resolved
    rows += write(3.5, 1, 0x1012, 0, 0x40000100)
    rows += write(4.0, 2, 0x1012, 0, 0x40000100)
    found = run(rows)
    assert [(round(f.t, 3), f.severity) for f in found] == [(2.001, "warning"), (4.001, "warning")]
    assert "2 SYNC producers: node 1's SYNC producer, node 2's SYNC producer" in found[0].message
    assert "0x1005 written at +1.001 s; 0x1005 written at +2.001 s" == found[0].basis
    assert "2 TIME producers" in found[1].message


def test_one_sync_producer_and_consumers_are_consistent():
    rows = heartbeats([1, 2], 3.0)
    rows += write(1.0, 1, 0x1005, 0, 0x40000080)
    rows += write(1.5, 2, 0x1005, 0, 0x80)
    assert run(rows) == []


def test_tpdo_shorter_than_the_rpdo_that_takes_it():
    rows = heartbeats([5, 6], 5.0)
    rows += write(1.0, 5, 0x1A00, 0, 1, 1)
    rows += write(1.1, 5, 0x1A00, 1, 0x60410010)  # 2 bytes
    rows += write(1.2, 6, 0x1600, 0, 2, 1)
    rows += write(1.3, 6, 0x1600, 1, 0x60400010)
    rows += write(1.4, 6, 0x1600, 2, 0x607A0020)  # 6 bytes
    rows += write(2.0, 6, 0x1400, 1, 0x185)  # node 6's RPDO1 takes node 5's TPDO1
    rows += write(3.0, 5, 0x1A00, 0, 0, 1)  # mapping being rewritten
    rows += write(3.1, 5, 0x1A00, 2, 0x607A0020)
    rows += write(3.2, 5, 0x1A00, 1, 0x60400010)
    rows += write(3.3, 5, 0x1A00, 0, 2, 1)  # the same 6 bytes: resolved
    network = {"nodes": {5: {"tpdo": {1: {"cob_id": 0x185}}}}}
    (f,) = run(rows, network)
    assert f.severity == "error" and f.cob_id == 0x185 and abs(f.t - 2.001) < 1e-6
    assert (f.measured, f.expected) == (2, 6)
    assert "node 5's TPDO1 maps 2 byte(s), node 6's RPDO1 that takes it maps 6" in f.message
    assert f.basis == (
        "0x1800:1 in the network file; 0x1400:1 written at +2.001 s; "
        "0x1A00 written at +1.001 s; 0x1600 written at +1.201 s"
    )


def test_tpdo_and_rpdo_of_one_length_are_consistent():
    rows = heartbeats([5, 6], 3.0)
    rows += write(1.0, 5, 0x1A00, 0, 1, 1)
    rows += write(1.1, 5, 0x1A00, 1, 0x60410010)
    rows += write(1.2, 6, 0x1600, 0, 1, 1)
    rows += write(1.3, 6, 0x1600, 1, 0x60400010)
    rows += write(2.0, 6, 0x1400, 1, 0x185)
    assert run(rows, {"nodes": {5: {"tpdo": {1: {"cob_id": 0x185}}}}}) == []
