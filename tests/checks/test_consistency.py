"""The `consistency` rule: a configuration that contradicts itself, told once, when it began."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
import yaml
from conftest import REAL, real_file

import cananalyze
from cananalyze.checks.engine import Checker
from cananalyze.checks.rules.consistency import ConsistencyRule
from cananalyze.core.frames import from_rows
from cananalyze.formats.logfile import write_log
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


def test_a_resolved_collision_back_with_the_same_objects_is_the_one_told():
    rows = heartbeats([5, 6], 8.0)
    rows += write(1.0, 5, 0x1800, 1, 0x190)
    rows += write(2.0, 6, 0x1800, 1, 0x190)
    rows += write(3.0, 6, 0x1800, 1, 0x191)  # resolved
    rows += write(4.0, 6, 0x1800, 1, 0x190)  # the same again (a master reconfiguring)
    rows += [(4.5, 0x000, b"\x81\x06")]  # node 6 reset: its TPDO1 back to nothing known
    rows += write(5.0, 6, 0x1802, 1, 0x190)  # back, with another object: a new one
    found = run(rows)
    assert [round(f.t, 3) for f in found] == [2.001, 5.001]
    assert "node 6's TPDO3" in found[1].message


def test_distinct_cob_ids_and_a_tpdo_with_its_rpdo_are_consistent():
    rows = heartbeats([5, 6], 4.0)
    rows += write(1.0, 5, 0x1800, 1, 0x190)
    rows += write(1.1, 6, 0x1800, 1, 0x191)
    rows += write(1.2, 6, 0x1400, 1, 0x190)  # node 6 consumes node 5's TPDO1: fine
    rows += write(1.3, 6, 0x1801, 1, 0x80000190)  # a not valid TPDO on it: no producer
    assert run(rows) == []


def test_a_tpdo_on_a_node_on_the_bus_predefined_cob_id_seen_on_the_wire():
    """Node 5 is on the bus (its heartbeat) and nothing moves its TPDO1 from 0x185 (CiA
    301's predefined connection set): node 6's TPDO2 configured on 0x185 collides."""
    rows = heartbeats([5], 4.0, period=0.1)
    rows = [r for r in rows if r[0] >= 0.5]  # node 5 shows itself at +0.500 s
    rows += heartbeats([6], 4.0)
    rows += write(0.2, 6, 0x1801, 1, 0x185)
    (f,) = run(rows)
    assert f.severity == "warning" and f.cob_id == 0x185 and f.node == 6
    assert abs(f.t - 0.5) < 1e-6  # when node 5 showed itself: the later of the two
    assert "node 6's TPDO2 is node 5's TPDO1 in the predefined connection set" in f.message
    assert f.basis == "0x1801:1 written at +0.201 s; node 5's TPDO1 0x185: CiA 301 predefined"


def test_a_predefined_cob_id_moved_away_or_of_a_node_not_on_the_bus_is_no_collision():
    rows = heartbeats([5, 6], 4.0)
    rows += write(0.2, 5, 0x1800, 1, 0x1A5)  # node 5's TPDO1 moved away
    rows += write(0.3, 6, 0x1801, 1, 0x185)
    rows += write(0.4, 6, 0x1802, 1, 0x189)  # node 9's TPDO1, but node 9 is not on the bus
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


# --- no false alarm: the bundled samples and the real logs ---------------------------
SAMPLES = Path(__file__).resolve().parents[2] / "samples"
_NOT_LOGS = {".eds", ".dcf", ".md", ".dbc", ".xdd", ".xdc", ".yml", ".yaml", ".py", ".csv"}
REAL_LOGS = sorted(
    str(p.relative_to(REAL))
    for p in (REAL.rglob("*") if REAL.exists() else ())
    if p.is_file() and p.suffix.lower() not in _NOT_LOGS and "EDS_Info" not in p.name
)
# real logs with the device descriptions they came with (node -> EDS/DCF)
PAIRED = {
    "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt": {
        1: "nigel-bruce-khan__ros_canopen-tmcm-1636/TMCM-1636-CANopen.dcf"
    },
    "jclinton830__canopen_test/candump.txt": {
        12: "jclinton830__canopen_test/roboteq_motor_controllers_v80.eds"
    },
    "SeonilChoi__CANOPEN-SDK/log2.txt": {11: "SeonilChoi__CANOPEN-SDK/ZeroErr_Driver_V1.5.eds"},
    "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log": {
        127: "calumroy__CANopen_socketCAN_Test/EDS-23123-1.01.eds"
    },
    **{
        f"isPointless__Sevcon/{log}": {
            1: "isPointless__Sevcon/ME1302 80V Size4 6000RPM FW SN0058-28.dcf"
        }
        for log in ("can_180209_154604.txt", "can_280109_111603.txt", "can_310309_094758.txt")
    },
}


def _consistency(path, **kw):
    f = cananalyze.load(path, **kw).findings
    return f[f.rule == "consistency"]


@pytest.mark.parametrize("name", ["commissioning", "faults", "demo"])
def test_samples_give_no_consistency_finding(name):
    """The bundled network configures heartbeats and PDOs by SDO: nothing contradicts."""
    found = _consistency(
        SAMPLES / f"{name}.log", network=SAMPLES / "network.toml", rules=SAMPLES / "rules.yaml"
    )
    assert len(found) == 0


@pytest.mark.parametrize("name", REAL_LOGS)
def test_real_logs_give_no_consistency_finding(name):
    """None of the real logs shows a configuration that contradicts itself (pcan1-3 and
    ixxat1 write 0x1016/0x1017 and TPDOs by SDO; node 1, watched, sends its heartbeat)."""
    assert len(_consistency(real_file(name))) == 0


@pytest.mark.parametrize("name", sorted(PAIRED))
def test_real_logs_with_their_device_descriptions_give_no_consistency_finding(name):
    eds = {node: real_file(path) for node, path in PAIRED[name].items()}
    assert len(_consistency(real_file(name), eds=eds)) == 0


def test_real_consumer_entries_judged_against_a_declared_producer_time(tmp_path):
    """pcan1's master writes 0x1016:1 = node 1, 4200 ms to nodes 15, 90 and 40 (node 15
    again after each of its boot-ups); declared at 5000 ms, node 1's heartbeat would be
    watched too tightly: one finding per consumer, from its first write."""
    log = real_file("hilch__canopen-message-interpreter/pcan1.trc")
    net = tmp_path / "net.toml"
    net.write_text("[nodes.1]\nheartbeat_ms = 5000\n")
    found = _consistency(log, network=net)
    assert list(found.node) == [15, 90, 40]
    assert set(found.cob_id) == {0x701} and set(found.severity) == {"warning"}
    assert set(found.measured) == {4200} and set(found.expected) == {5500}
    assert all(b.startswith("0x1016:1 written at") for b in found.basis)
    assert all(b.endswith("0x1017 in the network file") for b in found.basis)


def test_each_change_reads_only_the_node_it_changed(monkeypatch):
    """A commissioning log writes thousands of objects: each change reads the node it
    touched again, not every node (the whole network per write was 27 s on 10k writes)."""
    reads = []
    real_read = ConsistencyRule._read
    monkeypatch.setattr(
        ConsistencyRule,
        "_read",
        lambda self, ctx, node, t: reads.append(node) or real_read(self, ctx, node, t),
    )
    rows = heartbeats(range(1, 21), 3.0)
    writes = [(node, k) for k in range(5) for node in range(1, 21)]
    for i, (node, k) in enumerate(writes):
        rows += write(0.5 + i * 0.01, node, 0x1800 + k, 1, 0x180 + node + 0x20 * k)
    assert run(rows) == []
    # the first judgement reads the 20 nodes (the batch's writes are known by then); then
    # one read per write
    assert len(reads) == 20 + len(writes)


def test_a_real_dcf_that_puts_three_tpdos_on_one_cob_id(tmp_path):
    """OreSat's battery.dcf gives TPDO1, 5 and 9 all 0x40000180+$NODEID (valid): a node
    described by it produces three PDOs on one COB-ID, told from the first frame on, with
    the profile named as where the values came from."""
    dcf = real_file("oresat__CANopen-monitor/battery.dcf")
    rows = heartbeats([5], 2.0)
    log = tmp_path / "hb.log"
    write_log(from_rows(rows), log)
    found = _consistency(log, eds={5: dcf})
    assert list(found.cob_id) == [0x185, 0x285, 0x385, 0x485]
    assert set(found.severity) == {"error"} and set(found.t_rel) == {0.0}
    assert (
        found.message.iloc[0]
        == "COB-ID 0x185 claimed by node 5's TPDO1, node 5's TPDO5, node 5's TPDO9"
    )
    assert found.basis.iloc[0] == (
        "0x1800:1 profile default; 0x1804:1 profile default; 0x1808:1 profile default"
    )
