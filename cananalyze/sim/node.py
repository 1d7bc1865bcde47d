"""One simulated CANopen device: NMT state machine, heartbeat or guarding, SDO
server, TPDOs by transmission type, RPDOs into outputs, and EMCY.

Everything the node does is driven by its object dictionary, so a master's SDO
writes (heartbeat time, PDO remaps, event timers) change its behaviour exactly
as they would on the real device.
"""

from __future__ import annotations

import random
import struct
from dataclasses import dataclass, field

from cananalyze.core.frames import FLAG_RTR
from cananalyze.devices.profile import DeviceProfile
from cananalyze.protocol import nmt
from cananalyze.protocol.emcy import register_for
from cananalyze.protocol.nmt import BOOTUP, OPERATIONAL, PRE_OPERATIONAL, STOPPED
from cananalyze.sim import mpdo_producer, srdo_producer
from cananalyze.sim.dictionary import Dictionary
from cananalyze.sim.engine import Simulation
from cananalyze.sim.sdo_server import SdoServer
from cananalyze.sim.waveforms import Waveform, default_signals

SCAN_PERIOD = 0.010  # how often inputs are sampled for change-driven TPDOs
SDO_DELAY = 0.0004  # server processing time before a response


@dataclass
class Tpdo:
    number: int
    last: bytes | None = None
    last_sent: float = -1e9
    sync_count: int = 0
    pending: bool = False
    timer_token: int = 0
    snapshot: bytes | None = None  # type 252: data sampled at the last SYNC
    mpdo_sent: int = 0  # an MPDO's frames so far: the next carries the next object


@dataclass
class Faults:
    """Misbehaviour switched on by scenarios, as (start, end) windows in seconds."""

    heartbeat_off: list[tuple[float, float]] = field(default_factory=list)
    sdo_mute: list[tuple[float, float]] = field(default_factory=list)
    timer_stall: list[tuple[float, float]] = field(default_factory=list)
    srdo_not_inverted: list[tuple[float, float]] = field(default_factory=list)
    srdo_late: list[tuple[float, float]] = field(default_factory=list)  # past SRVT

    @staticmethod
    def inside(windows: list[tuple[float, float]], t: float) -> bool:
        return any(a <= t < b for a, b in windows)


class SimNode:
    """A CiA 301 slave built from a DeviceProfile."""

    def __init__(
        self,
        node_id: int,
        profile: DeviceProfile,
        rng: random.Random | None = None,
        signals: dict[tuple[int, int], Waveform] | None = None,
        boot_delay: float | None = None,
        config: list[tuple[int, int, int]] = (),
    ):
        self.node_id = node_id
        self.profile = profile
        self.rng = rng or random.Random(node_id)
        self.od = Dictionary(profile, node_id, config)
        self.sdo = SdoServer(self.od)
        self.signals = signals if signals is not None else default_signals(profile.key, self.rng)
        self.boot_delay = boot_delay if boot_delay is not None else self.rng.uniform(0.05, 0.3)
        self.state = BOOTUP
        self.faults = Faults()
        self.sim: Simulation | None = None
        self.tpdos: dict[int, Tpdo] = {}
        self._gen = 0  # bumped on every reset: events of an older life are ignored
        self._hb_gen = 0  # bumped when the heartbeat time changes
        self._hb_due = 0.0
        self._toggle = 0
        self.emcy_sent: list[tuple[float, int, int, bytes]] = []
        self._rpdo_pending: dict[int, bytes] = {}  # synchronous RPDOs wait for the next SYNC
        self._guard_token = 0
        self.life_guard_emcy = life_guard_emcy_for(profile.key)

    @property
    def generation(self) -> int:
        """Bumped on every reset and PDO restart: events of an older one are dropped."""
        return self._gen

    # --- life cycle ---------------------------------------------------------------------
    def start(self, sim: Simulation) -> None:
        self.sim = sim
        sim.at(sim.now + self.boot_delay, lambda: self._boot(communication_only=False))

    def _boot(self, communication_only: bool) -> None:
        self._gen += 1
        self.od.reset(communication_only)
        self.sdo.t = None
        self.tpdos = {}
        self._rpdo_pending = {}
        self._toggle = 0
        self._guard_token += 1
        self.state = PRE_OPERATIONAL
        self.sim.send(self, 0x700 + self.node_id, bytes([BOOTUP]))
        self._restart_heartbeat()

    def _restart_heartbeat(self) -> None:
        self._hb_gen += 1
        period = self.od.get(0x1017, 0) / 1000.0
        self._hb_due = self.sim.now + period
        if period > 0:
            gen, hb = self._gen, self._hb_gen
            self.sim.after(period, lambda: self._heartbeat(gen, hb, period))

    def _restart_pdos(self) -> None:
        """Forget PDO timers and state (a PDO parameter changed or the node left OPERATIONAL)."""
        self._gen += 1
        gen = self._gen
        hb_period = self.od.get(0x1017, 0) / 1000.0
        if hb_period > 0:  # the heartbeat keeps its rhythm across the new generation
            self._hb_gen += 1
            hb = self._hb_gen
            self.sim.after(self._hb_due - self.sim.now, lambda: self._heartbeat(gen, hb, hb_period))
        if self.state == OPERATIONAL:
            self._start_pdos()

    def _heartbeat(self, gen: int, hb: int, period: float) -> None:
        if gen != self._gen or hb != self._hb_gen:
            return
        if not Faults.inside(self.faults.heartbeat_off, self.sim.now):
            self.sim.send(self, 0x700 + self.node_id, bytes([self.state]))
        self._hb_due = self.sim.now + period
        self.sim.after(period, lambda: self._heartbeat(gen, hb, period))

    def set_state(self, state: int) -> None:
        old, self.state = self.state, state
        if state == OPERATIONAL and old != OPERATIONAL:
            self._start_pdos()
        elif state != OPERATIONAL and old == OPERATIONAL:
            self._restart_pdos()  # stops input scan and timers

    # --- frames in ---------------------------------------------------------------------
    def on_frame(self, cob: int, data: bytes, flags: int) -> None:
        nid = self.node_id
        if cob == 0x000 and len(data) >= 2 and data[1] in (nmt.ALL_NODES, nid):
            self._nmt(data[0])
        elif self.state == BOOTUP:
            return
        elif cob == 0x700 + nid and flags & FLAG_RTR:  # node guarding request
            self.sim.after(SDO_DELAY, lambda: self._guard_reply())
        elif self.state == STOPPED:
            return
        elif cob == 0x600 + nid and not flags & FLAG_RTR:
            self._sdo_request(data)
        elif cob == 0x080 and not flags & FLAG_RTR:
            if self.state == OPERATIONAL:
                self._on_sync()
        elif self.state == OPERATIONAL:
            self._pdo_frame(cob, data, flags)

    def _nmt(self, cs: int) -> None:
        state = nmt.COMMAND_STATE.get(cs)
        if state == BOOTUP:  # a reset: the node boots again
            self.state = BOOTUP
            self._gen += 1
            only_comm = cs == nmt.RESET_COMMUNICATION
            self.sim.after(0.02, lambda: self._boot(communication_only=only_comm))
        elif state is not None:
            self.set_state(state)

    def _guard_reply(self) -> None:
        toggle = nmt.TOGGLE_BIT if self._toggle else 0
        self.sim.send(self, 0x700 + self.node_id, bytes([self.state | toggle]))
        self._toggle ^= 1
        self._arm_life_guarding()

    def _arm_life_guarding(self) -> None:
        """Life guarding: no guard request within guard time x life time factor is an error."""
        life = self.od.get(0x100C, 0) * self.od.get(0x100D, 0) / 1000.0
        self._guard_token += 1
        if life <= 0:
            return
        token, gen = self._guard_token, self._gen

        def expire() -> None:
            if token == self._guard_token and gen == self._gen:
                self.life_guard_emcy(self)

        self.sim.after(life, expire)

    def _sdo_request(self, data: bytes) -> None:
        if Faults.inside(self.faults.sdo_mute, self.sim.now):
            return
        self._sample_inputs()  # reads of input objects see the current measurement
        before = dict(self.od.values)
        responses = self.sdo.handle(data)
        changed = {k for k, v in self.od.values.items() if before.get(k) != v}
        delay = SDO_DELAY + self.rng.uniform(0, 0.0006)  # firmware response time varies
        for k, resp in enumerate(responses):
            self.sim.after(
                delay + k * 1e-6, lambda r=resp: self.sim.send(self, 0x580 + self.node_id, r)
            )
        if any(k[0] == 0x1017 for k in changed):
            self._restart_heartbeat()
        elif any(0x1800 <= k[0] < 0x1C00 for k in changed) and self.state == OPERATIONAL:
            self._restart_pdos()

    # --- TPDOs ----------------------------------------------------------------------------
    def tpdo_params(self, n: int) -> tuple[int, bool, bool, int, float, float] | None:
        """(cob_id, valid, rtr_allowed, transmission type, inhibit s, event timer s) of TPDO n."""
        base = 0x1800 + n - 1
        if not self.od.has(base, 1):
            return None
        cob = self.od.get(base, 1)
        return (
            cob & 0x7FF,
            not cob & 0x80000000,
            not cob & 0x40000000,
            self.od.get(base, 2, 255),
            self.od.get(base, 3) * 100e-6,
            self.od.get(base, 5) / 1000.0,
        )

    def tpdo_payload(self, n: int) -> bytes:
        """The mapped objects of TPDO n, packed little-endian bit by bit (CiA 301 7.4.7);
        an MPDO's next frame (mpdo_producer)."""
        base = 0x1A00 + n - 1
        if mpdo_producer.mode(self.od, n) is not None:
            pdo = self.tpdos.get(n)
            return mpdo_producer.frame(self.od, self.node_id, n, pdo.mpdo_sent if pdo else 0)
        acc = bits = 0
        for sub in range(1, self.od.get(base, 0) + 1):
            word = self.od.get(base, sub)
            index, subindex, length = word >> 16, (word >> 8) & 0xFF, word & 0xFF
            if 0x1 <= index < 0x1000:  # dummy entry
                value = 0
            else:
                raw = self.od.values.get((index, subindex), b"")
                value = int.from_bytes(raw, "little") if raw else 0
            acc |= (value & ((1 << length) - 1)) << bits
            bits += length
        return acc.to_bytes((bits + 7) // 8, "little")[:8]

    def _sample_inputs(self) -> None:
        t = self.sim.now
        for (index, sub), wave in self.signals.items():
            self.od.set(index, sub, wave(t))

    def _start_pdos(self) -> None:
        gen = self._gen
        self.tpdos = {}
        for n in range(1, 513):
            params = self.tpdo_params(n)
            if params is None:
                if n > 8:
                    break
                continue
            self.tpdos[n] = Tpdo(n)
            if params[1] and params[3] >= 254 and params[5] > 0:
                self._arm_timer(n, params[5])
        srdo_producer.start(self)
        self.sim.after(0.0, lambda: self._scan(gen))

    def _scan(self, gen: int) -> None:
        if gen != self._gen or self.state != OPERATIONAL:
            return
        self._sample_inputs()
        for n in self.tpdos:
            params = self.tpdo_params(n)
            if params and params[1] and params[3] >= 254 and not self._mpdo(n):
                self._maybe_send(n, params)  # an MPDO's objects take turns: by its timer only
        self.sim.after(SCAN_PERIOD, lambda: self._scan(gen))

    def _maybe_send(self, n: int, params) -> None:
        pdo = self.tpdos[n]
        payload = self.tpdo_payload(n)
        if payload == pdo.last or pdo.pending:
            return  # unchanged, or a send is due when the inhibit time ends: it samples then
        ready = pdo.last_sent + params[4] + 1e-6 if params[4] else 0.0  # 1 us: clear of rounding
        if self.sim.now >= ready:
            # in real time a scan due before `ready` can run after it: without the pending
            # check above it sent here and the pending send again, 0.3 ms later
            self.send_tpdo(n)
        else:  # inhibit time: send when it has passed
            pdo.pending = True
            gen = self._gen

            def later() -> None:
                pdo.pending = False
                if gen == self._gen and self.state == OPERATIONAL:
                    self.send_tpdo(n)

            self.sim.at(ready, later)

    def send_tpdo(self, n: int) -> None:
        """Transmit TPDO n now with current values (fault scenarios call this to break the inhibit time)."""
        params = self.tpdo_params(n)
        if params is None or not params[1] or not self.od.get(0x1A00 + n - 1, 0):
            return  # not valid, or nothing mapped
        pdo = self.tpdos.setdefault(n, Tpdo(n))
        self._sample_inputs()
        payload = self.tpdo_payload(n)
        if self._mpdo(n):
            if not payload:
                return  # no object to send
            pdo.mpdo_sent += 1
        pdo.last = payload
        # the inhibit time runs from when the frame really went out (the bus may have been busy)
        pdo.last_sent = self.sim.send(self, params[0], payload)
        if params[3] >= 254 and params[5] > 0:
            self._arm_timer(n, params[5])

    def _mpdo(self, n: int) -> bool:
        return mpdo_producer.mode(self.od, n) is not None

    def _arm_timer(self, n: int, period: float) -> None:
        pdo = self.tpdos[n]
        pdo.timer_token += 1
        token, gen = pdo.timer_token, self._gen

        def expire() -> None:
            if gen != self._gen or token != pdo.timer_token or self.state != OPERATIONAL:
                return
            if Faults.inside(self.faults.timer_stall, self.sim.now):
                self.sim.after(SCAN_PERIOD, expire)  # late: the event timer is violated
                return
            self.send_tpdo(n)

        self.sim.after(period, expire)

    def _on_sync(self) -> None:
        for n, data in sorted(self._rpdo_pending.items()):
            self._apply_rpdo(n, data)
        self._rpdo_pending = {}
        self._sample_inputs()
        for n, pdo in self.tpdos.items():
            params = self.tpdo_params(n)
            if not params or not params[1]:
                continue
            ttype = params[3]
            if ttype == 252:  # synchronous RTR-only: sample now, send on request
                pdo.snapshot = self.tpdo_payload(n)
            elif ttype == 0:  # synchronous acyclic: on SYNC, only if the data changed
                if self.tpdo_payload(n) != pdo.last:
                    self.send_tpdo(n)
            elif 1 <= ttype <= 240:
                pdo.sync_count += 1
                if pdo.sync_count >= ttype:
                    pdo.sync_count = 0
                    self.send_tpdo(n)

    def _pdo_frame(self, cob: int, data: bytes, flags: int) -> None:
        if flags & FLAG_RTR:
            for n in self.tpdos:
                params = self.tpdo_params(n)
                if params and params[1] and params[2] and params[0] == cob:
                    self.sim.after(SDO_DELAY, lambda n=n: self._answer_rtr(n))
            return
        for n in range(1, 513):
            base = 0x1400 + n - 1
            if not self.od.has(base, 1):
                if n > 8:
                    break
                continue
            cob_param = self.od.get(base, 1)
            if cob_param & 0x80000000 or cob_param & 0x7FF != cob:
                continue
            if self.od.get(base, 2, 255) <= 240:  # synchronous: takes effect at the next SYNC
                self._rpdo_pending[n] = bytes(data)
            else:
                self._apply_rpdo(n, data)

    def _answer_rtr(self, n: int) -> None:
        pdo = self.tpdos.get(n)
        params = self.tpdo_params(n)
        if pdo is not None and params and params[3] == 252 and pdo.snapshot is not None:
            pdo.last, pdo.last_sent = pdo.snapshot, self.sim.send(self, params[0], pdo.snapshot)
        else:
            self.send_tpdo(n)

    def _apply_rpdo(self, n: int, data: bytes) -> None:
        """Write the RPDO's bytes into the mapped output objects."""
        base = 0x1600 + n - 1
        value = int.from_bytes(data, "little")
        bits = 0
        for sub in range(1, self.od.get(base, 0) + 1):
            word = self.od.get(base, sub)
            index, subindex, length = word >> 16, (word >> 8) & 0xFF, word & 0xFF
            part = (value >> bits) & ((1 << length) - 1)
            bits += length
            if index >= 0x1000 and self.od.has(index, subindex):
                old = self.od.values[(index, subindex)]
                if length < 8 * len(old):  # a bit-mapped output: merge into the byte
                    cur = int.from_bytes(old, "little")
                    shift = sum(  # position of this bit among entries mapping the same object
                        1 for s in range(1, sub) if self.od.get(base, s) >> 8 == word >> 8
                    )
                    cur = (cur & ~(((1 << length) - 1) << shift)) | part << shift
                    self.od.set_raw(index, subindex, cur.to_bytes(len(old), "little"))
                else:
                    self.od.set_raw(index, subindex, part.to_bytes(len(old), "little"))

    # --- EMCY -------------------------------------------------------------------------------
    def emcy(self, error_code: int, register: int | None = None, manufacturer: bytes = b"") -> None:
        """Send an emergency (CiA 301 7.2.7) and keep 0x1001/0x1003 in step."""
        if self.state not in (PRE_OPERATIONAL, OPERATIONAL):
            return
        if register is None:
            register = register_for(error_code)
        self.od.set(0x1001, 0, register)
        if error_code and self.od.has(0x1003, 1):
            count = min(self.od.get(0x1003, 0) + 1, 254)
            for sub in range(count, 1, -1):
                if self.od.has(0x1003, sub):
                    self.od.set(0x1003, sub, self.od.get(0x1003, sub - 1))
            # low word the error code, high word manufacturer info (as the I-7231D's 00 FF 0B 02)
            extra = int.from_bytes(bytes(manufacturer)[:2].ljust(2, b"\x00"), "little")
            self.od.set(0x1003, 1, error_code | extra << 16)
            self.od.set(0x1003, 0, sum(1 for s in range(1, count + 1) if self.od.has(0x1003, s)))
        cob = self.od.get(0x1014, 0, 0x80 + self.node_id) & 0x7FF or 0x80 + self.node_id
        data = struct.pack("<HB", error_code, register) + bytes(manufacturer).ljust(5, b"\x00")[:5]
        self.emcy_sent.append((self.sim.now, error_code, register, data[3:]))
        self.sim.send(self, cob, data)


def generic_life_guard_emcy(node: SimNode) -> None:
    node.emcy(0x8130)


def life_guard_emcy_for(key: str):
    """How a device reports a life-guarding error: CiA 301 0x8130 plus its vendor bytes."""
    if key == "mcb560":
        return lambda node: mcb560_emcy(node, 0x8130, 0x30000000)
    if key == "i7231d":
        return lambda node: i7231d_emcy(node, 0x8130, 0x07)  # "life guarding fails"
    return generic_life_guard_emcy


def mcb560_emcy(node: SimNode, error_code: int, chip_ec: int) -> None:
    """MCB-560 emergency: byte 3 zero, bytes 4-7 the CO4201 Chip-EC (manual 004)."""
    node.emcy(error_code, None, b"\x00" + struct.pack("<I", chip_ec))


def i7231d_emcy(node: SimNode, error_code: int, vendor_code: int, module_address: int = 0) -> None:
    """I-7231D emergency: byte 3 the ICP DAS error code, byte 4 the RS-485 module address."""
    node.emcy(error_code, None, bytes([vendor_code, module_address]))
