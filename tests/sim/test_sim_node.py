"""Simulated node behaviour on the discrete-event clock: NMT, heartbeat, guarding,
TPDO transmission types, RPDOs, EMCY; and determinism for a seed."""

from __future__ import annotations

import random
import struct

import numpy as np

from cananalyze.core.frames import FLAG_RTR
from cananalyze.devices.builtin import load_builtin
from cananalyze.sim.engine import Simulation
from cananalyze.sim.master import Guard, Nmt, Read, Send, Sync, Until, Wait, Write, u8, u16, u32
from cananalyze.sim.node import SimNode, i7231d_emcy, mcb560_emcy
from cananalyze.sim.session import simulate


def run(key: str, node_id: int, script, duration: float):
    sim = Simulation()
    node = sim.add(SimNode(node_id, load_builtin(key), random.Random(1), boot_delay=0.1))
    from cananalyze.sim.master import Master

    master = sim.add(Master(script(node)))
    sim.run(duration)
    return sim.batch(), node, master


def times(batch, cob, data=None):
    sel = batch.can_id == cob
    t = batch.t[sel] - 1767225600.0
    return t, [batch.payload(int(i)) for i in np.flatnonzero(sel)]


def test_boot_heartbeat_and_nmt_states():
    def script(node):
        yield Wait(0.2)
        yield Write(5, 0x1017, 0, u16(100))
        yield Until(1.0)
        yield Nmt(0x01, 5)
        yield Until(2.0)
        yield Nmt(0x02, 0)
        yield Until(3.0)
        yield Nmt(0x82, 5)  # reset communication: boot-up again, heartbeat back to 0

    batch, node, _ = run("dat7014", 5, script, 4.0)
    t, data = times(batch, 0x705)
    assert data[0] == b"\x00" and abs(t[0] - 0.1) < 1e-3
    states = {round(tt, 1): d[0] for tt, d in zip(t[1:], data[1:], strict=True)}
    assert states[0.5] == 0x7F and states[1.5] == 0x05 and states[2.5] == 0x04
    assert np.allclose(np.diff(t[1:-1]), 0.1, atol=1e-3)
    assert data[-1] == b"\x00" and 3.0 < t[-1] < 3.1  # boot-up after the reset, then silence
    assert node.state == 0x7F


def test_node_guarding_toggles():
    def script(node):
        yield Wait(0.2)
        yield Guard(7, 0.1)

    batch, _, _ = run("i7231d", 7, script, 1.0)
    replies = [d[0] for d in times(batch, 0x707)[1] if d][1:]  # skip boot-up
    assert len(replies) == 8
    assert [r >> 7 for r in replies] == [0, 1] * 4
    assert {r & 0x7F for r in replies} == {0x7F}


def test_sync_cyclic_sync_acyclic_and_rtr():
    def script(node):
        yield Wait(0.2)
        yield Write(6, 0x1800, 2, u8(3))  # digital inputs: every 3rd SYNC
        yield Write(6, 0x1801, 2, u8(0))  # counters 1-2: on SYNC when changed
        yield Write(6, 0x1802, 2, u8(253))  # counters 3-4: RTR only
        yield Write(6, 0x1803, 1, u32(0x80000486))
        yield Nmt(0x01)
        yield Sync(0.1)
        yield Until(1.05)
        yield Send(0x386, b"", FLAG_RTR)

    batch, node, _ = run("dat7130", 6, script, 2.0)
    t_sync, _ = times(batch, 0x080)
    t1, _ = times(batch, 0x186)
    assert len(t1) == len(t_sync) // 3
    assert np.allclose(np.diff(t1), 0.3, atol=1e-3)
    t2, d2 = times(batch, 0x286)
    assert len(t2) < len(t_sync) and all(
        a != b for a, b in zip(d2[:-1], d2[1:], strict=True)
    )  # only changes
    t3, d3 = times(batch, 0x386)
    assert len(t3) == 2 and 1.05 < t3[1] < 1.06  # the RTR (empty) and the answer
    assert d3[0] == b"" and len(d3[1]) == 8
    assert len(times(batch, 0x486)[0]) == 0  # disabled


def test_event_timer_and_inhibit_time():
    def script(node):
        yield Wait(0.2)
        yield Write(3, 0x1800, 3, u16(2000))  # digital inputs: inhibit 200 ms
        yield Write(3, 0x1801, 5, u16(300))  # analog: event timer 300 ms
        yield Write(3, 0x1802, 1, u32(0x80000383))
        yield Nmt(0x01)

    sim = Simulation()
    node = SimNode(3, load_builtin("mcb560"), random.Random(1), boot_delay=0.1)
    node.signals[(0x6000, 1)] = lambda t: int(t * 20) & 1  # toggles every 50 ms
    node.signals = {k: v for k, v in node.signals.items() if k[0] != 0x6401}  # analog frozen
    from cananalyze.sim.master import Master

    sim.add(node)
    sim.add(Master(script(node)))
    sim.run(3.0)
    batch = sim.batch()
    t_di, _ = times(batch, 0x183)
    assert np.diff(t_di).min() >= 0.2 and np.diff(t_di).max() < 0.21
    t_ai, _ = times(batch, 0x283)
    assert np.allclose(np.diff(t_ai), 0.3, atol=1e-3)


def test_rpdo_sets_outputs():
    def script(node):
        yield Wait(0.2)
        yield Nmt(0x01)
        yield Wait(0.1)
        yield Send(0x207, bytes([0xA5, 0x3C, 0x01]))
        yield Send(0x307, struct.pack("<H", 2048))
        yield Wait(0.1)
        yield Read(7, 0x6200, 2)

    _, node, master = run("i7231d", 7, script, 1.0)
    assert [node.od.get(0x6200, s) for s in (1, 2, 3)] == [0xA5, 0x3C, 0x01]
    assert node.od.get(0x6411, 1) == 2048
    assert master.results[-1][1] == b"\x3c"


def test_emcy_manufacturer_fields_and_history():
    def script(node):
        yield Wait(0.2)
        yield Until(0.3)
        mcb560_emcy(node, 0x8130, 0x10000000)
        yield Wait(0.1)
        yield Read(3, 0x1001, 0)

    batch, node, master = run("mcb560", 3, script, 1.0)
    _, data = times(batch, 0x083)
    assert data == [bytes.fromhex("3081110000000010")]
    assert master.results[-1][1] == b"\x11"  # generic + communication
    prof = load_builtin("mcb560")
    decoded = prof.decode_emcy(0x8130, 0x11, data[0][3:])
    assert decoded["chip_ec"] == 0x10000000 and "heartbeat error" in decoded["flags"]

    sim = Simulation()
    gw = sim.add(SimNode(7, load_builtin("i7231d"), boot_delay=0.0))
    sim.at(0.1, lambda: i7231d_emcy(gw, 0xFF00, 0x0B, 0x02))
    sim.run(0.5)
    _, data = times(sim.batch(), 0x087)
    assert data == [bytes.fromhex("00FF810B02000000")]
    # the manual's 0x1003 entry for this error reads 00 FF 0B 02
    assert gw.od.values[(0x1003, 1)] == bytes.fromhex("00FF0B02")
    assert load_builtin("i7231d").decode_emcy(0xFF00, 0x81, data[0][3:])["module_address"] == 2


def test_same_seed_same_frames_other_seed_differs():
    a = simulate(scenario="steady", duration=2.0, seed=3)
    b = simulate(scenario="steady", duration=2.0, seed=3)
    c = simulate(scenario="steady", duration=2.0, seed=4)
    assert np.array_equal(a.t, b.t) and np.array_equal(a.data, b.data)
    assert len(a) != len(c) or not np.array_equal(a.t, c.t)


def test_synchronous_rpdo_waits_for_sync_and_rtr_only_252_sends_the_sync_sample():
    def script(node):
        yield Wait(0.2)
        yield Write(7, 0x1400, 2, u8(1))  # RPDO1 synchronous
        yield Write(7, 0x1801, 2, u8(252))  # TPDO2 (AI): sampled at SYNC, sent on RTR
        yield Nmt(0x01)
        yield Wait(0.1)
        yield Send(0x207, bytes([0x11, 0x22, 0x33]))
        yield Wait(0.05)
        assert node.od.get(0x6200, 1) == 0  # not applied before the SYNC
        yield Send(0x080)
        yield Wait(0.05)
        assert [node.od.get(0x6200, s) for s in (1, 2, 3)] == [0x11, 0x22, 0x33]
        yield Until(1.0)
        yield Send(0x287, b"", FLAG_RTR)

    sim = Simulation()
    node = SimNode(7, load_builtin("i7231d"), random.Random(1), boot_delay=0.1)
    node.signals[(0x6401, 1)] = lambda t: int(t * 1000)  # changes every millisecond
    from cananalyze.sim.master import Master

    sim.add(node)
    master = sim.add(Master(script(node)))
    sim.run(1.5)
    assert master.results and all(isinstance(r, bytes) for _, r in master.results)
    batch = sim.batch()
    t, data = times(batch, 0x287)
    answer = [d for d in data if d]
    assert len(answer) == 1  # only the RTR answer, with the value sampled at the SYNC
    t_sync = times(batch, 0x080)[0][0]
    assert abs(struct.unpack("<h", answer[0])[0] / 1000 - t_sync) < 0.002


def test_life_guarding_error_emcy_per_device():
    for key, nid, expected in (
        ("mcb560", 3, "3081110000000030"),  # Chip-EC 0x30000000: life-guarding error
        ("i7231d", 7, "3081110700000000"),  # ICP DAS code 0x07: life guarding fails
    ):

        def script(node, nid=nid):
            yield Wait(0.2)
            yield Write(nid, 0x100C, 0, u16(100))
            yield Write(nid, 0x100D, 0, u8(3))
            yield Guard(nid, 0.1)
            yield Wait(0.5)
            yield Guard(nid, 0)  # the master stops guarding

        batch, node, _ = run(key, nid, script, 2.0)
        t, data = times(batch, 0x80 + nid)
        assert [d.hex().upper() for d in data] == [expected]
        last_guard = times(batch, 0x700 + nid)[0][-1]
        assert abs(t[0] - last_guard - 0.3) < 0.01  # guard time x life time factor
