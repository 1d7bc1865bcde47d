"""Named scenarios: what the master does and which faults happen when.

Each scenario is a master script (see master.py) over the simulated nodes. They
work on any network; device-specific steps (a DAT 7014 remap, MCB-560 Chip-EC
emergencies) apply to the nodes of that device and are skipped otherwise.
"""

from __future__ import annotations

from collections.abc import Callable

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT
from cananalyze.protocol import nmt
from cananalyze.sim.master import Do, Guard, Nmt, Read, Send, Sync, Until, Wait, Write, u8, u16, u32
from cananalyze.sim.node import SimNode, i7231d_emcy, mcb560_emcy
from cananalyze.sim.waveforms import Override

Nodes = dict[int, SimNode]
HEARTBEAT_MS = 100
SYNC_PERIOD = 0.1


def _of(nodes: Nodes, key: str) -> list[SimNode]:
    return [n for _, n in sorted(nodes.items()) if n.profile.key == key]


def _write(node: SimNode, index: int, sub: int, data: bytes):
    """A Write for an object the node has; None (skipped) otherwise."""
    return Write(node.node_id, index, sub, data) if node.od.has(index, sub) else None


def _identity(nodes: Nodes):
    for nid, node in sorted(nodes.items()):
        for index, sub in ((0x1000, 0), (0x1018, 1), (0x1018, 2), (0x1018, 3), (0x1008, 0)):
            if node.od.has(index, sub):
                yield Read(nid, index, sub)


def _supervision(nodes: Nodes):
    """Heartbeat 100 ms where 0x1017 exists, else node guarding 100 ms x 3."""
    for nid, node in sorted(nodes.items()):
        if node.od.has(0x1017, 0):
            yield Write(nid, 0x1017, 0, u16(HEARTBEAT_MS))
        elif node.od.has(0x100C, 0):
            yield Write(nid, 0x100C, 0, u16(HEARTBEAT_MS))
            yield Write(nid, 0x100D, 0, u8(3))


def _guarding(nodes: Nodes):
    for nid, node in sorted(nodes.items()):
        if not node.od.has(0x1017, 0) and node.od.has(0x100C, 0):
            yield Guard(nid, HEARTBEAT_MS / 1000)


def _remap_dat7014(node: SimNode):
    """TPDO2 remap: only channels 1 and 3, sent on every 5th SYNC (CiA 301 remap procedure)."""
    nid, cob = node.node_id, 0x280 + node.node_id
    yield Write(nid, 0x1801, 1, u32(0x80000000 | cob))  # disable the PDO
    yield Write(nid, 0x1A01, 0, u8(0))  # disable the mapping
    yield Write(nid, 0x1A01, 1, u32(0x64010110))
    yield Write(nid, 0x1A01, 2, u32(0x64010310))
    yield Write(nid, 0x1A01, 0, u8(2))
    yield Write(nid, 0x1801, 2, u8(5))  # cyclic synchronous, every 5th SYNC
    yield Write(nid, 0x1801, 1, u32(cob))  # enable again


def _configure(nodes: Nodes):
    """Transmission types, inhibit times and event timers per device."""
    for node in _of(nodes, "dat7014"):
        yield from _remap_dat7014(node)
    for node in _of(nodes, "mcb560"):
        yield _write(node, 0x1800, 3, u16(1000))  # digital inputs: inhibit 100 ms
        yield _write(node, 0x1801, 3, u16(1000))  # analog: inhibit 100 ms
        yield _write(node, 0x1801, 5, u16(200))  # and at least every 200 ms
        yield _write(node, 0x1802, 1, u32(0x80000380 + node.node_id))  # analog 4-7: not wired
    for node in _of(nodes, "dat7130"):
        yield _write(node, 0x1801, 2, u8(0))  # counters 1-2: synchronous acyclic
        for n in (2, 3):  # counters 3-8: event-driven, event timer 1 s
            yield _write(node, 0x1802 + n - 2, 2, u8(254))
            yield _write(node, 0x1802 + n - 2, 5, u16(1000))
    for node in _of(nodes, "i7231d"):
        yield _write(node, 0x1800, 3, u16(200))  # DI: inhibit 20 ms
        yield _write(node, 0x1801, 5, u16(250))  # AI: event timer 250 ms
        yield _write(node, 0x1802, 1, u32(0x80000380 + node.node_id))  # empty PDOs off
        yield _write(node, 0x1803, 1, u32(0x80000480 + node.node_id))


def _outputs(nodes: Nodes, k: int):
    """RPDOs from the master: DAT 7130 relay outputs and I-7231D DO bytes."""
    for node in _of(nodes, "dat7130"):
        yield Send(0x200 + node.node_id, bytes([k & 0x0F]))
    for node in _of(nodes, "i7231d"):
        yield Send(0x200 + node.node_id, bytes([1 << (k % 8), 0xFF if k % 2 else 0, 0]))


def _run_outputs(nodes: Nodes, start: float, end: float, period: float = 1.0):
    k = 0
    t = start
    while t < end:
        yield Until(t)
        yield from _outputs(nodes, k)
        k += 1
        t = start + k * period


def _drop_none(script):
    value = None
    while True:
        try:
            cmd = script.send(value)
        except StopIteration:
            return
        value = None if cmd is None else (yield cmd)


def steady(nodes: Nodes, duration: float):
    """Boot, heartbeat or guarding, start, SYNC and PDOs: plain traffic."""
    yield Wait(0.4)
    yield from _supervision(nodes)
    yield Nmt(nmt.START)
    yield Sync(SYNC_PERIOD)
    yield from _guarding(nodes)
    yield from _run_outputs(nodes, 1.0, duration)


def commissioning(nodes: Nodes, duration: float):
    """Boot, identity reads (expedited, segmented, one block), configuration with
    a PDO remap, start, then steady operation."""
    yield Wait(0.4)
    yield from _identity(nodes)
    first = next((n for n in _of(nodes, "dat7130")), None) or next(iter(nodes.values()))
    yield Read(first.node_id, 0x1008, 0, block=True)
    yield from _supervision(nodes)
    yield from _configure(nodes)
    yield Wait(0.05)
    yield Nmt(nmt.START)
    yield Sync(SYNC_PERIOD)
    yield from _guarding(nodes)
    yield from _run_outputs(nodes, 2.0, duration)


def faults(nodes: Nodes, duration: float):
    """Steady operation with faults at fixed times (see samples/README.md)."""
    yield Wait(0.4)
    yield from _supervision(nodes)
    yield from _configure(nodes)
    yield Nmt(nmt.START)
    yield Sync(SYNC_PERIOD)
    yield from _guarding(nodes)
    mcb = _of(nodes, "mcb560")
    dat14 = _of(nodes, "dat7014")
    dat30 = _of(nodes, "dat7130")
    gw = _of(nodes, "i7231d")

    def each(group: list[SimNode], fn: Callable[[SimNode], None]) -> Do:
        return Do(lambda: [fn(n) for n in group])

    yield Until(1.5)  # MCB-560: CAN error warning, heartbeat error, bus off and back, reset
    yield each(mcb, lambda n: mcb560_emcy(n, 0x8100, 0x40000000))
    yield Until(2.0)
    yield each(mcb, lambda n: mcb560_emcy(n, 0x8130, 0x10000000))
    yield Until(2.5)
    for _ in range(3):
        yield Send(
            0x004, bytes([0, 0x04, 0, 0, 0, 0, 0, 0]), FLAG_ERR | FLAG_EXT
        )  # controller problem
        yield Wait(0.001)
    yield Until(2.6)
    yield each(mcb, lambda n: mcb560_emcy(n, 0x8140, 0xC0000000))
    yield Until(3.0)
    yield each(mcb, lambda n: mcb560_emcy(n, 0x0000, 0x00000000))
    yield Until(3.2)  # I-7231D: RS-485 module 0x02 timed out (manual's 00 FF 0B 02)
    yield each(gw, lambda n: i7231d_emcy(n, 0xFF00, 0x0B, 0x02))
    yield Until(3.5)  # DAT 7014 channel 3 out of range (sensor open: saturated reading)
    for node in dat14:
        wave = node.signals[(0x6401, 3)]
        node.signals[(0x6401, 3)] = Override(wave, 0x7FFF, 3.5, 5.0)
        yield Read(node.node_id, 0x6401, 3)
    yield Until(4.5)  # DAT 7130 heartbeat stops for 1.5 s
    for node in dat30:
        node.faults.heartbeat_off.append((4.5, 6.0))
    yield Until(6.5)  # MCB-560 TPDO1 twice within its 100 ms inhibit time
    yield each(mcb, lambda n: n.send_tpdo(1))
    yield Wait(0.02)
    yield each(mcb, lambda n: n.send_tpdo(1))
    yield Until(7.0)  # SDO aborts: a read-only object, a missing object
    for node in dat14:
        yield Write(node.node_id, 0x1018, 1, u32(0))
    for node in mcb:
        yield Read(node.node_id, 0x2FFF, 0)
    yield Until(7.2)  # MCB-560 analog inputs freeze: TPDO2 only by its 200 ms event timer,
    for node in mcb:  # which stalls from 8.0 to 8.6 s
        node.faults.timer_stall.append((8.0, 8.6))
        node.signals = {k: v for k, v in node.signals.items() if k[0] != 0x6401}
    yield Until(7.5)  # DAT 7014 stops answering SDO: the master times out after 1 s
    for node in dat14:
        node.faults.sdo_mute.append((7.5, 9.0))
        yield Read(node.node_id, 0x1008, 0)
    yield Until(duration)


SCENARIOS = {"steady": steady, "commissioning": commissioning, "faults": faults}


def script(name: str, nodes: Nodes, duration: float):
    """The master script of a named scenario (steps for absent objects are skipped)."""
    return _drop_none(SCENARIOS[name](nodes, duration))
