"""Named scenarios: what the master does and which faults happen when.

Each scenario is a master script (see master.py) over the simulated nodes. They
work on any network; device-specific steps (a DAT 7014 remap, MCB-560 Chip-EC
emergencies) apply to the nodes of that device and are skipped otherwise.
"""

from __future__ import annotations

import random
from collections.abc import Callable

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT
from cananalyze.protocol import lss, nmt, sdo
from cananalyze.sim.lss_slave import LssSlave
from cananalyze.sim.master import (
    Do,
    Guard,
    Nmt,
    Read,
    SdoError,
    Send,
    Sync,
    Until,
    Wait,
    Write,
    u8,
    u16,
    u32,
)
from cananalyze.sim.node import SimNode, i7231d_emcy, mcb560_emcy
from cananalyze.sim.scenario_names import SCENARIO_NAMES
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


def _remap_dat7014(node: SimNode, cob: int | None = None):
    """TPDO2 remap: only channels 1 and 3, sent on every 5th SYNC (CiA 301 remap procedure)."""
    nid, cob = node.node_id, cob or 0x280 + node.node_id
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


LSS_SERIAL = 0x00012345  # the serial number of the unconfigured device LSS configures
SYNC_WINDOW_US = 20_000  # 0x1007 the master writes where it configures 0x1006
JITTER = (4.0, 6.0, 0.03)  # SYNC jitter: from, to (s), up to +-30 ms


def _lss_assign(nodes: Nodes, slave: LssSlave, node_id: int):
    """Switch selective by the identity, configure node-ID, store, back to waiting."""

    def join() -> None:
        sim = next(iter(nodes.values())).sim
        sim.add(slave)
        slave.start(sim)

    yield Do(join)
    for cs, value in zip(lss.SELECTIVE, slave.identity, strict=True):
        yield Send(lss.MASTER_COB, (bytes([cs]) + u32(value)).ljust(8, b"\x00"))
        yield Wait(0.005)
    for data in (
        bytes([lss.CODES["configure node-ID"], node_id]),
        bytes([lss.CODES["store configuration"]]),
        bytes([lss.CODES["switch state global"], lss.WAITING]),
    ):
        yield Send(lss.MASTER_COB, data.ljust(8, b"\x00"))
        yield Wait(0.01)
    yield Do(lambda: nodes.__setitem__(node_id, slave.node))


def _identity_ok(node: SimNode):
    """Read vendor-ID and product code and compare them with the node's declared device,
    as a CiA 302-2 master does (0x1F85, 0x1F86); False stops the node's boot."""
    ok = True
    for sub, want in ((1, node.profile.vendor_id), (2, node.profile.product_code)):
        if not node.od.has(0x1018, sub):
            continue
        got = yield Read(node.node_id, 0x1018, sub)
        if isinstance(got, SdoError) or (want and int.from_bytes(got, "little") != want):
            ok = False
    return ok


def _configured(node: SimNode, writes):
    """Carry out a node's configuration writes; False at the first abort (boot stopped)."""
    for cmd in writes:
        if cmd is None:
            continue
        if isinstance((yield cmd), SdoError):
            return False
    return True


def commissioning_faults(nodes: Nodes, duration: float):
    """Commissioning with one fault of each kind that `cananalyze boot`, the LSS table,
    SYNC timing and `consistency` should find (docs/simulator.md): an LSS master gives an
    unconfigured DAT 7014 a node-ID; the master checks identities and stops the boot of a
    DAT 7014 whose product code differs from its declared one; a DAT 7130 aborts a
    configuration write, so it is not started either; the I-7231D is configured but never
    started; the LSS node's TPDO2 is put on the MCB-560's TPDO2 COB-ID; SYNC jitters."""
    dat14, dat30, gw, mcb = (_of(nodes, k) for k in ("dat7014", "dat7130", "i7231d", "mcb560"))
    wrong, refusing = dat14[:1], dat30[:1]
    forgotten = gw[:1]

    def inject() -> None:
        for node in wrong:  # another product than the one declared for the node
            node.od.config.append((0x1018, 2, (node.profile.product_code or 0) + 1))
        for node in refusing:  # counters 1-2 cannot be synchronous acyclic on this one
            node.sdo.abort_codes[(0x1801, 2)] = sdo.ABORT_VALUE_RANGE

    yield Do(inject)  # before the nodes boot
    yield Wait(0.4)
    profile = (dat14 or list(nodes.values()))[0].profile
    lss_id = next(n for n in range(10, 128) if n not in nodes)
    rng = random.Random(next(iter(nodes.values())).rng.getrandbits(32))
    slave = LssSlave(profile, LSS_SERIAL, rng)
    yield from _lss_assign(nodes, slave, lss_id)
    yield Wait(0.4)  # the new node boots
    good = []
    for _, node in sorted(nodes.items()):
        if (yield from _identity_ok(node)):
            good.append(node)
    started = []
    for node in good:
        one = {node.node_id: node}
        writes = [*_supervision(one)]
        writes += [_write(node, 0x1006, 0, u32(int(SYNC_PERIOD * 1e6)))]
        writes += [_write(node, 0x1007, 0, u32(SYNC_WINDOW_US))]
        collide = node is slave.node and node.profile.key == "dat7014"
        if collide and mcb and mcb[0].tpdo_params(2):
            writes += [*_remap_dat7014(node, cob=mcb[0].tpdo_params(2)[0])]  # the collision
        else:
            writes += [*_configure(one)]
        if (yield from _configured(node, writes)) and node not in forgotten:
            started.append(node)
    yield Wait(0.05)
    for node in started:
        yield Nmt(nmt.START, node.node_id)
    yield Sync(SYNC_PERIOD)
    yield from _guarding({n.node_id: n for n in good})
    yield Until(JITTER[0])
    yield Sync(SYNC_PERIOD, jitter=JITTER[2])
    yield Until(JITTER[1])
    yield Sync(SYNC_PERIOD)
    yield Until(duration)


# safety-faults: (start, end) s of each SRDO fault: the first pair in it has it
SRDO_FAULTS = {"srdo_not_inverted": (2.0, 3.0), "srdo_late": (3.0, 4.0)}


def safety(nodes: Nodes, duration: float):
    """Steady operation of a network file's safety and multiplexed traffic: the nodes'
    SRDOs (`[nodes.N.srdo.K]`) and MPDOs (a TPDO's `mpdo`, `object_scanner_list`) run on
    their own once started (sim/srdo_producer.py, sim/mpdo_producer.py)."""
    yield from steady(nodes, duration)


def safety_faults(nodes: Nodes, duration: float):
    """`safety` with, from SRDO_FAULTS, one SRDO pair whose inverted frame is not the bit
    inversion (at 2 s) and one whose inverted frame comes past SRVT (at 3 s)."""

    def inject() -> None:
        for node in nodes.values():
            for fault, window in SRDO_FAULTS.items():
                getattr(node.faults, fault).append(window)

    yield Do(inject)
    yield from steady(nodes, duration)


# fd: the USDO client's node-ID (CiA 1301: its COB-ID 0x600 + it) and the data type codes
USDO_CLIENT = 0x7F
_VISIBLE_STRING, _UNSIGNED16, _UNSIGNED32, _DOMAIN = 0x09, 0x06, 0x07, 0x0F
USDO_DOMAIN = 0x2F00


def _usdo(nodes: Nodes):
    """CiA 1301 USDO traffic (CAN FD frames, encoded by protocol/usdo.py's table) between a
    client (node USDO_CLIENT) and every simulated node, the servers' answers from their
    object dictionaries: an expedited read (0x1018:01) and write (0x1017), a segmented
    read (0x1008), a bulk write of 150 bytes (USDO_DOMAIN), and on the first node a read
    of an object it does not have (0x5FFF:00: abort 0x33)."""
    from cananalyze.core.frames import FLAG_BRS, FLAG_FD
    from cananalyze.protocol import usdo

    fd = FLAG_FD | FLAG_BRS
    c = USDO_CLIENT

    def client(n: int, cs: int, session: int, **f) -> Send:
        return Send(usdo.CLIENT_BASE + c, usdo.encode(cs, n, session, **f), fd)

    def server(n: int, cs: int, session: int, **f) -> Send:
        return Send(usdo.SERVER_BASE + n, usdo.encode(cs, c, session, **f), fd)

    def abort(n: int, session: int, index: int, sub: int, code: int) -> Send:
        return server(n, usdo.ABORT, session, index=index, subindex=sub, abort_code=code)

    gap = 0.001
    for k, node in enumerate(sorted(nodes.values(), key=lambda x: x.node_id)):
        n, od, s = node.node_id, node.od, 4 * k + 1
        mux = dict(index=0x1018, subindex=1)
        yield client(n, 0x11, s, **mux)
        yield Wait(gap)
        if od.has(0x1018, 1):
            yield server(n, 0x31, s, **mux, datatype=_UNSIGNED32, data=od.read(0x1018, 1))
        else:
            yield abort(n, s, 0x1018, 1, 0x33)
        yield Wait(gap)
        mux = dict(index=0x1017, subindex=0)
        value = u16(od.get(0x1017, 0, 0))  # its own value: the write changes nothing
        yield client(n, 0x01, s + 1, **mux, datatype=_UNSIGNED16, data=value)
        yield Wait(gap)
        yield server(n, 0x21, s + 1, **mux)
        yield Wait(gap)
        # segmented read of the device name, 60 bytes a segment
        mux = dict(index=0x1008, subindex=0)
        yield client(n, 0x11, s + 2, **mux)
        yield Wait(gap)
        if not od.has(0x1008, 0):
            yield abort(n, s + 2, 0x1008, 0, 0x33)
        else:
            name = od.read(0x1008, 0)
            yield server(n, 0x32, s + 2, **mux, datatype=_VISIBLE_STRING, total=len(name))
            parts = [name[i : i + usdo.SEGMENT_MAX] for i in range(0, len(name), usdo.SEGMENT_MAX)]
            for i, part in enumerate(parts or [b""]):
                yield Wait(gap)
                yield client(n, 0x13, s + 2, counter=i)
                yield Wait(gap)
                last = i == len(parts or [b""]) - 1
                yield server(n, 0x34 if last else 0x33, s + 2, counter=i, data=part)
        yield Wait(gap)
        # bulk write: segments back to back, one answer at the end (the server keeps
        # nothing: a manufacturer DOMAIN the simulated devices do not declare)
        blob = bytes((7 * i + n) & 0xFF for i in range(150))
        mux = dict(index=USDO_DOMAIN, subindex=0)
        yield client(n, 0x06, s + 3, **mux, datatype=_DOMAIN, total=len(blob))
        yield Wait(gap)
        yield server(n, 0x26, s + 3, **mux)
        parts = [blob[i : i + usdo.SEGMENT_MAX] for i in range(0, len(blob), usdo.SEGMENT_MAX)]
        for i, part in enumerate(parts):
            yield Wait(gap / 4)
            yield client(n, 0x08 if i == len(parts) - 1 else 0x07, s + 3, counter=i, data=part)
        yield Wait(gap)
        yield server(n, 0x28, s + 3, counter=len(parts) - 1)
        yield Wait(gap)
        if k == 0:  # one read of an object the device does not have: an abort
            yield client(n, 0x11, 0xFF, index=0x5FFF, subindex=0)
            yield Wait(gap)
            yield abort(n, 0xFF, 0x5FFF, 0, 0x33)
            yield Wait(gap)


def fd(nodes: Nodes, duration: float):
    """A CANopen FD network (CiA 1301): steady operation with USDO transfers (expedited,
    segmented, bulk, an abort) from 1 s on (`_usdo`)."""
    yield Wait(0.4)
    yield from _supervision(nodes)
    yield Nmt(nmt.START)
    yield Sync(SYNC_PERIOD)
    yield Until(1.0)
    yield from _usdo(nodes)
    yield from _run_outputs(nodes, 1.5, duration)


# each name is the script of the same name ("-" for "_")
SCENARIOS = {name: globals()[name.replace("-", "_")] for name in SCENARIO_NAMES}


def script(name: str, nodes: Nodes, duration: float):
    """The master script of a named scenario (steps for absent objects are skipped)."""
    return _drop_none(SCENARIOS[name](nodes, duration))
