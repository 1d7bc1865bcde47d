"""The expected value at each frame: the log's last write or read-back, else the network
file's, else the profile's; a reset returns to the declared value; 0 from the log or a
file is off. Traffic from the simulator (simulated clock) and from python-canopen."""

from __future__ import annotations

import random
import time

import pytest
from conftest import real_file

import cananalyze
from cananalyze.core.frames import from_rows
from cananalyze.devices.builtin import load_builtin
from cananalyze.formats.logfile import write_log
from cananalyze.sim.engine import START, Simulation
from cananalyze.sim.master import Guard, Master, Nmt, Read, Until, Write, u16
from cananalyze.sim.node import SimNode


def simulate(tmp_path, script, key="dat7014", node_id=5, config=(), duration=5.0, setup=None):
    """A log of one simulated device and a master running `script(node)`."""
    sim = Simulation()
    node = sim.add(SimNode(node_id, load_builtin(key), random.Random(1), config=list(config)))
    if setup is not None:
        setup(node)
    sim.add(Master(script(node)))
    sim.run(duration)
    log = tmp_path / "sim.log"
    write_log(sim.batch(), log)
    return log


def network(tmp_path, text: str):
    path = tmp_path / "net.toml"
    path.write_text(text)
    return path


def findings(cap, rule: str, t0: float = START) -> list[tuple[float, float, float, str]]:
    """(time after t0, measured, expected, severity) of one rule's findings."""
    f = cap.findings[cap.findings.rule == rule]
    return [(round(r.t - t0, 2), r.measured, r.expected, r.severity) for r in f.itertuples()]


def at(seconds: float) -> float:
    return START + seconds


NET_100 = '[nodes.5]\ndevice = "dat7014"\nheartbeat_ms = 100\n'


def test_heartbeat_written_off_then_300_no_finding_between(tmp_path):
    def script(node):
        yield Nmt(0x01)
        yield Until(1.0)
        yield Write(5, 0x1017, 0, u16(0))  # heartbeats stop
        yield Until(2.5)
        yield Write(5, 0x1017, 0, u16(300))  # and come back every 300 ms

    log = simulate(tmp_path, script, config=[(0x1017, 0, 100)])
    cap = cananalyze.load(log, network=network(tmp_path, NET_100))
    assert cap.heartbeat(5)["max"] > 1400  # the silence is in the log
    assert [cap.config.heartbeat_ms(5, at(s)) for s in (0.5, 1.5, 3.0)] == [100, 0, 300]
    assert findings(cap, "heartbeat") == []


def test_heartbeat_read_back_tells_the_period(tmp_path):
    def script(node):
        yield Nmt(0x01)
        yield Until(0.8)
        yield Read(5, 0x1017, 0)

    def silent(node):
        node.faults.heartbeat_off.append((2.0, 2.5))

    log = simulate(tmp_path, script, config=[(0x1017, 0, 100)], setup=silent)
    cap = cananalyze.load(log, device={5: "dat7014"})  # nothing declared: 0 is the profile's
    assert cap.config.heartbeat_ms(5, at(0.5)) is None
    assert cap.config.heartbeat_ms(5, at(1.0)) == 100
    (drop,) = findings(cap, "heartbeat")
    assert drop[1:] == (pytest.approx(600, abs=1), 100.0, "error")  # judged, not inferred


def test_network_file_value_then_the_log_write_from_its_time_on(tmp_path):
    def script(node):
        yield Nmt(0x01)
        yield Until(2.0)
        yield Write(5, 0x1017, 0, u16(300))

    def silent(node):
        node.faults.heartbeat_off += [(1.0, 1.3), (3.0, 3.7)]

    log = simulate(tmp_path, script, config=[(0x1017, 0, 100)], setup=silent)
    cap = cananalyze.load(log, network=network(tmp_path, NET_100))
    found = findings(cap, "heartbeat")
    # before the write: a 400 ms gap against the file's 100; after it: 900 ms against 300,
    # and the 300 ms heartbeats in between are not dropouts
    assert [(t, e) for t, _, e, _ in found] == [(pytest.approx(0.9, abs=0.11), 100.0),
                                                (pytest.approx(2.9, abs=0.31), 300.0)]  # fmt: skip
    assert [m for _, m, _, _ in found] == [pytest.approx(400, abs=1), pytest.approx(900, abs=1)]


@pytest.mark.parametrize("how", ["nmt reset", "own reset"])
def test_reset_returns_to_the_network_file_value(tmp_path, how):
    """The log switches the heartbeat off; after the node's reset the file's 100 ms holds
    again, so a later gap is a dropout."""

    def script(node):
        yield Nmt(0x01)
        yield Until(1.0)
        yield Write(5, 0x1017, 0, u16(0))
        yield Until(2.0)
        if how == "nmt reset":
            yield Nmt(0x81, 5)
        else:
            node._boot(communication_only=False)  # a watchdog reset: boot-up, no command
        yield Nmt(0x01)

    def silent(node):
        node.faults.heartbeat_off.append((3.0, 3.5))

    log = simulate(tmp_path, script, config=[(0x1017, 0, 100)], setup=silent)
    cap = cananalyze.load(log, network=network(tmp_path, NET_100))
    assert [cap.config.heartbeat_ms(5, at(s)) for s in (1.5, 2.5)] == [0, 100]
    assert [(t, m, e) for t, m, e, _ in findings(cap, "heartbeat")] == [
        (pytest.approx(2.9, abs=0.11), pytest.approx(600, abs=1), 100.0)
    ]


def test_zero_in_the_file_is_off_a_profile_zero_is_unknown(tmp_path):
    def silent(node):
        node.faults.heartbeat_off.append((2.0, 3.0))

    def script(node):
        yield Nmt(0x01)

    log = simulate(tmp_path, script, config=[(0x1017, 0, 100)], setup=silent)
    off = network(tmp_path, '[nodes.5]\ndevice = "dat7014"\nheartbeat_ms = 0\n')
    assert findings(cananalyze.load(log, network=off), "heartbeat") == []
    unknown = cananalyze.load(log, device={5: "dat7014"})  # profile 0: period inferred
    assert [(t, s) for t, _, _, s in findings(unknown, "heartbeat")] == [
        (pytest.approx(1.9, abs=0.11), "warning")
    ]


def test_guard_time_read_back_and_change_judged_at_each_request(tmp_path):
    def script(node):
        yield Until(0.5)
        yield Read(7, 0x100C, 0)  # 100 ms, the device's stored value (nothing declared)
        yield Guard(7, 0.1)
        yield Until(2.0)
        yield Guard(7, 0.13)  # one late request period ...
        yield Until(2.5)
        yield Write(7, 0x100C, 0, u16(300))  # ... then the master slows down, and says so
        yield Guard(7, 0.3)

    log = simulate(
        tmp_path, script, "i7231d", 7, config=[(0x100C, 0, 100), (0x100D, 0, 3)], duration=4.0
    )
    cap = cananalyze.load(log, device={7: "i7231d"})
    period = [f for f in findings(cap, "guarding") if f[2] in (100.0, 300.0)]
    assert {e for _, _, e, _ in period} == {100.0}  # only the 130 ms requests, against 100
    assert all(2.0 < t < 2.6 for t, _, _, _ in period) and len(period) >= 3


def _pdo_log(tmp_path, before_ms: int, after_ms: int, sdo: list):
    """Node 5 runs, TPDO2 (0x285) every `before_ms` until 1 s, then every `after_ms`."""
    rows = [(0.0, 0x705, b"\x00"), (0.01, 0x000, b"\x01\x05")]
    rows += [(0.05 * k, 0x705, b"\x05") for k in range(1, 80)]
    t = 0.1
    while t < 1.0:
        rows.append((round(t, 4), 0x285, b"\x00\x00"))
        t += before_ms / 1000
    rows += sdo
    t = 1.1
    while t < 3.9:
        rows.append((round(t, 4), 0x285, b"\x00\x00"))
        t += after_ms / 1000
    log = tmp_path / "pdo.log"
    write_log(from_rows(sorted(rows, key=lambda r: r[0])), log)
    return log


def _write_rows(t: float, index: int, sub: int, value: int, size: int = 4) -> list:
    """An expedited SDO download of `size` bytes to node 5 and its confirmation."""
    cmd = {1: 0x2F, 2: 0x2B, 4: 0x23}[size]
    req = bytes([cmd, index & 0xFF, index >> 8, sub]) + value.to_bytes(4, "little")
    resp = bytes([0x60, index & 0xFF, index >> 8, sub, 0, 0, 0, 0])
    return [(t, 0x605, req), (t + 0.001, 0x585, resp)]


def test_pdo_event_timer_written_mid_batch_applies_from_the_write_on(tmp_path):
    net = network(
        tmp_path,
        "[nodes.5.tpdo.2]\ncob_id = 0x285\ntransmission_type = 254\nevent_timer = 500\nlength = 2\n",
    )
    log = _pdo_log(tmp_path, 500, 100, _write_rows(1.02, 0x1801, 5, 100))
    cap = cananalyze.load(log, network=net)
    assert findings(cap, "pdo_async") == [] and findings(cap, "pdo_length") == []
    assert cap.config.pdo_params(0x285, 0.5)[1].event_timer == 500
    assert cap.config.pdo_params(0x285, 1.5)[1].event_timer == 100
    # a log whose PDOs stay every 500 ms after the write breaks the new timer, from then on
    slow = cananalyze.load(
        _pdo_log(tmp_path, 500, 500, _write_rows(1.02, 0x1801, 5, 100)), network=net
    )
    late = findings(slow, "pdo_async", t0=0.0)
    assert late and all(t > 1.0 and e == 100 for t, _, e, _ in late)


def test_sync_period_written_mid_batch(tmp_path):
    rows = [(0.1 * k, 0x080, b"") for k in range(1, 11)]
    rows += _write_rows(1.02, 0x1006, 0, 50000)
    rows += [(1.05 + 0.05 * k, 0x080, b"") for k in range(40)]
    log = tmp_path / "sync.log"
    write_log(from_rows(sorted(rows, key=lambda r: r[0])), log)
    net = network(tmp_path, "[sync]\nperiod_us = 100000\n")
    cap = cananalyze.load(log, network=net)
    assert findings(cap, "sync") == []
    assert cap.config.sync_period_us(0.5) == 100000 and cap.config.sync_period_us(2.0) == 50000


def test_pdo_disabled_by_sdo_is_valid_again_after_boot_up(tmp_path):
    """Decoding follows the same rule: a reset returns the node's PDOs to the profile's."""
    pdo = bytes(8)
    rows = [(0.0, 0x705, b"\x00"), (0.01, 0x000, b"\x01\x05"), (0.1, 0x285, pdo)]
    rows += _write_rows(0.2, 0x1801, 1, 0x80000285)
    rows += [(0.3, 0x285, pdo), (0.4, 0x285, pdo), (0.5, 0x705, b"\x00"), (0.6, 0x285, pdo)]
    log = tmp_path / "reset.log"
    write_log(from_rows(rows), log)
    cap = cananalyze.load(log, device={5: "dat7014"})
    ((valid,),) = [
        tuple(f.measured for f in cap.findings[cap.findings.rule == "pdo_not_valid"].itertuples())
    ]
    assert valid == 2  # the two frames between the write and the boot-up
    decoded = cap.signals[cap.signals.signal == "ch1"]
    assert round(decoded.t.max(), 2) == 0.6  # and decoded after the reset


# --- real logs -----------------------------------------------------------------------------
def test_real_sevcon_mapping_read_back_decodes_and_is_not_a_short_mapping():
    """The master reads node 1's PDO mappings entry by entry while the PDOs run: from the
    read-backs on they are decoded, and never judged by a half-read mapping."""
    cap = cananalyze.load(real_file("isPointless__Sevcon/can_180209_154604.txt"))
    tpdo1 = cap.signals[(cap.signals.node == 1) & (cap.signals.pdo == "tpdo1")]
    assert set(tpdo1.signal) == {f"obj_4600_{k:02x}" for k in (5, 6, 7, 8)}
    reads = [c for c in cap.config.model.history if c.object == (0x1A00, 1)]
    assert reads and all(c.how == "read" for c in reads) and tpdo1.t.min() > reads[0].t
    assert (cap.findings.rule == "pdo_length").sum() == 0


def test_real_pcan3_nmt_reset_is_not_a_heartbeat_dropout():
    """The master resets node 85 (NMT reset node) and configures 0x1017 = 1400 again: the
    2.9 s without heartbeats around that is the reset, judged from the new 0x1017 on."""
    cap = cananalyze.load(real_file("hilch__canopen-message-interpreter/pcan3.trc"))
    t0 = float(cap.batch.t[0])
    f = cap.findings
    near = f[(f.rule == "heartbeat") & (f.node == 85) & ((f.t - t0).between(349, 352))]
    assert near.empty
    writes = [
        c.t - t0 for c in cap.config.model.history if c.node == 85 and c.object == (0x1017, 0)
    ]
    assert any(350.9 < w < 351.1 for w in writes)


# --- python-canopen: a real SDO client and heartbeat producer on a virtual bus ----------
@pytest.mark.slow
def test_canopen_heartbeat_off_then_300_and_read_back(tmp_path):
    import can
    import canopen
    from canopen.objectdictionary import UNSIGNED16

    from tests.helpers.virtual_bus import drain, patient_client, unique_channel, variable

    channel = unique_channel("hb")
    od = canopen.ObjectDictionary()
    od.add_object(variable(0x1017, 0, "Producer heartbeat time", UNSIGNED16, "rw", 100))
    slave, master = canopen.Network(), canopen.Network()
    slave.connect(interface="virtual", channel=channel)
    master.connect(interface="virtual", channel=channel)
    recorder = can.Bus(interface="virtual", channel=channel)
    try:
        local = canopen.LocalNode(5, od)
        slave.add_node(local)
        remote = patient_client(5)
        master.add_node(remote)
        local.nmt.state = "OPERATIONAL"  # a heartbeat of state 0 would be a boot-up
        local.nmt.start_heartbeat(100)
        time.sleep(0.6)
        remote.sdo.download(0x1017, 0, (0).to_bytes(2, "little"))  # off: no heartbeat expected
        time.sleep(1.0)
        remote.sdo.download(0x1017, 0, (300).to_bytes(2, "little"))
        time.sleep(1.5)
        assert int.from_bytes(remote.sdo.upload(0x1017, 0), "little") == 300  # a read-back
        time.sleep(0.3)
        local.nmt.stop_heartbeat()
        frames = drain(recorder)
    finally:
        local.nmt.stop_heartbeat()
        master.disconnect()
        slave.disconnect()
        recorder.shutdown()
    log = tmp_path / "canopen.log"
    write_log(from_rows([(m.timestamp, m.arbitration_id, bytes(m.data)) for m in frames]), log)
    rules = tmp_path / "rules.yaml"  # virtual-bus timing jitters: judge loosely
    rules.write_text(
        "rules: {heartbeat: {tolerance: 0.5}}\nnetwork:\n  nodes:\n    5: {heartbeat_ms: 100}\n"
    )
    cap = cananalyze.load(log, rules=rules)
    writes = [c for c in cap.checker.config.model.history if c.object == (0x1017, 0)]
    assert [(c.value, c.how) for c in writes] == [(0, "write"), (300, "write"), (300, "read")]
    assert cap.config.heartbeat_ms(5, writes[0].t + 0.5) == 0
    assert cap.config.heartbeat_ms(5, writes[1].t + 0.5) == 300
    assert cap.heartbeat(5)["max"] > 900  # the silence is in the log ...
    assert findings(cap, "heartbeat") == []  # ... and no finding for it
