"""The master role: NMT commands, an SDO client, a SYNC producer and node guarding,
driven by a scenario script.

A script is a generator that yields commands (`Wait`, `Nmt`, `Read`, `Write`,
`Sync`, `Guard`, `Do`); the master carries each out on the simulated clock and
sends the result (value bytes, or an `SdoError`) back into the generator, so a
scenario reads like the commissioning procedure it stands for.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable, Generator
from dataclasses import dataclass, field

from cananalyze.core.defaults import SDO_TIMEOUT
from cananalyze.core.frames import FLAG_ERR, FLAG_RTR, FLAG_TX
from cananalyze.protocol import sdo
from cananalyze.protocol.crc import crc16
from cananalyze.protocol.sdo import block_byte, initiate_byte, segment_byte
from cananalyze.protocol.sync import next_counter
from cananalyze.sim.engine import Simulation


@dataclass(frozen=True)
class Wait:
    seconds: float


@dataclass(frozen=True)
class Until:
    t: float  # seconds since the start


@dataclass(frozen=True)
class Nmt:
    command: int  # an NMT command specifier (protocol.nmt: START, STOP, ...)
    node: int = 0  # 0 = all nodes


@dataclass(frozen=True)
class Read:
    node: int
    index: int
    subindex: int = 0
    block: bool = False


@dataclass(frozen=True)
class Write:
    node: int
    index: int
    subindex: int
    data: bytes


@dataclass(frozen=True)
class Sync:
    period: float  # seconds; 0 stops the producer
    counter: int = 0  # > 0: SYNC with a counter byte overflowing at this value
    # seconds: each SYNC comes up to this much early or late (a fault); a Sync of the
    # period and counter already produced changes only the jitter, keeping the phase
    jitter: float = 0.0


@dataclass(frozen=True)
class Guard:
    node: int
    period: float  # 0 stops guarding


@dataclass(frozen=True)
class Send:
    cob: int
    data: bytes = b""
    flags: int = 0


@dataclass(frozen=True)
class Do:
    action: Callable[[], None]


@dataclass
class SdoError:
    """An SDO request that ended in an abort (code) or a timeout (code sdo.ABORT_TIMEOUT)."""

    code: int
    timeout: bool = False


def u8(v: int) -> bytes:
    return struct.pack("<B", v)


def u16(v: int) -> bytes:
    return struct.pack("<H", v)


def u32(v: int) -> bytes:
    return struct.pack("<I", v)


Script = Generator[object, object, None]


@dataclass
class _Client:
    cmd: Read | Write
    state: str
    data: bytearray = field(default_factory=bytearray)
    toggle: int = 0
    pos: int = 0
    seq: int = 0
    size: int = 0
    token: int = 0


class Master:
    """The network master; frames it sends carry the log's TX direction flag."""

    def __init__(
        self,
        script: Script | None = None,
        sdo_timeout: float = SDO_TIMEOUT,
        blksize: int = 16,
        rng: random.Random | None = None,
    ):
        self.script = script
        self.rng = rng or random.Random(0)  # SYNC jitter: deterministic per seed
        self.sdo_timeout = sdo_timeout
        self.blksize = blksize
        self.sim: Simulation | None = None
        self.client: _Client | None = None
        self.results: list[tuple[Read | Write, object]] = []
        self._sync_token = 0
        self._sync_count = 0
        self._sync_due = 0.0  # when the next SYNC is due without jitter
        self._sync_jitter = 0.0
        self._sync_running: tuple[float, int] | None = None  # (period, counter) producing
        self._guards: dict[int, int] = {}
        self._token = 0

    def start(self, sim: Simulation) -> None:
        self.sim = sim
        if self.script is not None:
            sim.at(sim.now, lambda: self._advance(None))

    def send(self, cob: int, data: bytes = b"", flags: int = 0) -> None:
        # error frames are the bus's, not the master's: no TX direction flag
        self.sim.send(self, cob, data, flags if flags & FLAG_ERR else flags | FLAG_TX)

    # --- script ---------------------------------------------------------------------
    def _advance(self, value: object) -> None:
        while True:
            try:
                cmd = self.script.send(value)
            except StopIteration:
                return
            value = None
            if isinstance(cmd, Wait):
                self.sim.after(cmd.seconds, lambda: self._advance(None))
                return
            if isinstance(cmd, Until):
                self.sim.at(max(cmd.t, self.sim.now), lambda: self._advance(None))
                return
            if isinstance(cmd, (Read, Write)):
                self._sdo_start(cmd)
                return
            if isinstance(cmd, Nmt):
                self.send(0x000, bytes([cmd.command, cmd.node]))
            elif isinstance(cmd, Sync):
                self._sync_jitter = cmd.jitter
                if cmd.period > 0 and self._sync_running == (cmd.period, cmd.counter):
                    continue  # the producer running: only its jitter changes, its phase stays
                self._sync_token += 1
                self._sync_running = (cmd.period, cmd.counter) if cmd.period > 0 else None
                if cmd.period > 0:
                    self._sync_due = self.sim.now
                    self._sync(self._sync_token, cmd.period, cmd.counter)
            elif isinstance(cmd, Guard):
                self._guards[cmd.node] = self._guards.get(cmd.node, 0) + 1
                if cmd.period > 0:
                    self._guard(cmd.node, self._guards[cmd.node], cmd.period)
            elif isinstance(cmd, Send):
                self.send(cmd.cob, cmd.data, cmd.flags)
            elif isinstance(cmd, Do):
                cmd.action()
            else:
                raise TypeError(f"unknown master command {cmd!r}")

    def _sync(self, token: int, period: float, counter: int) -> None:
        if token != self._sync_token:
            return
        if counter:
            self._sync_count = next_counter(self._sync_count, counter)
            self.send(0x080, bytes([self._sync_count]))
        else:
            self.send(0x080)
        j = self._sync_jitter
        if j:  # around the nominal grid, so the mean period stays `period`
            self._sync_due += period
            at = max(self._sync_due + self.rng.uniform(-j, j), self.sim.now)
        else:  # a period after this one
            at = self._sync_due = self.sim.now + period
        self.sim.at(at, lambda: self._sync(token, period, counter))

    def _guard(self, node: int, token: int, period: float) -> None:
        if token != self._guards.get(node):
            return
        self.send(0x700 + node, b"", FLAG_RTR)
        self.sim.after(period, lambda: self._guard(node, token, period))

    # --- SDO client -------------------------------------------------------------------
    def _sdo_start(self, cmd: Read | Write) -> None:
        self._token += 1
        mux = struct.pack("<HB", cmd.index, cmd.subindex)
        if isinstance(cmd, Read):
            self.client = _Client(cmd, "block_init" if cmd.block else "up_init", token=self._token)
            if cmd.block:  # CRC supported, blksize, no protocol switch
                head = block_byte(sdo.CCS_BLOCK_UPLOAD, sdo.BLOCK_INITIATE, crc=True)
                self._req(bytes([head]) + mux + bytes([self.blksize, 0, 0, 0]))
            else:
                self._req(bytes([sdo.INITIATE_UPLOAD_REQUEST]) + mux + b"\x00" * 4)
        else:
            data = cmd.data
            self.client = _Client(cmd, "down_init", data=bytearray(data), token=self._token)
            if len(data) <= sdo.EXPEDITED_SIZE:
                head = initiate_byte(sdo.CCS_INITIATE_DOWNLOAD, len(data), expedited=True)
                self._req(bytes([head]) + mux + data.ljust(4, b"\x00"))
            else:
                head = initiate_byte(sdo.CCS_INITIATE_DOWNLOAD, len(data))
                self._req(bytes([head]) + mux + u32(len(data)))
        self._arm_timeout()

    def _req(self, data: bytes) -> None:
        self.send(0x600 + self.client.cmd.node, data)

    def _arm_timeout(self) -> None:
        c = self.client
        c.token = self._token = self._token + 1
        token = c.token

        def expire() -> None:
            if self.client is c and c.token == token:
                mux = struct.pack("<HB", c.cmd.index, c.cmd.subindex)
                self._req(bytes([sdo.ABORT]) + mux + u32(sdo.ABORT_TIMEOUT))
                self._finish(SdoError(sdo.ABORT_TIMEOUT, timeout=True))

        self.sim.after(self.sdo_timeout, expire)

    def _finish(self, result: object) -> None:
        cmd = self.client.cmd
        self.client = None
        self.results.append((cmd, result))
        self.sim.after(0.002, lambda: self._advance(result))

    def on_frame(self, cob: int, data: bytes, flags: int) -> None:
        c = self.client
        if c is None or cob != 0x580 + c.cmd.node or flags & FLAG_RTR:
            return
        data = bytes(data).ljust(8, b"\x00")
        if data[0] == sdo.ABORT:
            self._finish(SdoError(struct.unpack_from("<I", data, 4)[0]))
            return
        if c.state == "block_data":
            self._block_segment(data)
            return
        scs = sdo.command_specifier(data[0])
        mux = struct.pack("<HB", c.cmd.index, c.cmd.subindex)
        self._arm_timeout()
        if c.state == "up_init" and scs == sdo.SCS_INITIATE_UPLOAD:
            if data[0] & sdo.EXPEDITED:
                self._finish(data[4 : 4 + sdo.expedited_size(data[0])])
            else:
                c.state = "up_seg"
                self._req(bytes([segment_byte(sdo.CCS_UPLOAD_SEGMENT, 0)]) + b"\x00" * 7)
        elif c.state == "up_seg" and scs == sdo.SCS_UPLOAD_SEGMENT:
            n = sdo.SEGMENT_SIZE - sdo.segment_unused(data[0])
            c.data += data[1 : 1 + n]
            if data[0] & sdo.LAST_SEGMENT:
                self._finish(bytes(c.data))
            else:
                c.toggle ^= 1
                self._req(bytes([segment_byte(sdo.CCS_UPLOAD_SEGMENT, c.toggle)]) + b"\x00" * 7)
        elif c.state == "down_init" and scs == sdo.SCS_INITIATE_DOWNLOAD:
            if len(c.data) <= sdo.EXPEDITED_SIZE:
                self._finish(b"")
            else:
                c.state = "down_seg"
                self._down_segment()
        elif c.state == "down_seg" and scs == sdo.SCS_DOWNLOAD_SEGMENT:
            if c.pos >= len(c.data):
                self._finish(b"")
            else:
                c.toggle ^= 1
                self._down_segment()
        elif c.state == "block_init" and scs == sdo.SCS_BLOCK_UPLOAD:
            c.size = struct.unpack_from("<I", data, 4)[0]
            c.state = "block_data"
            c.seq = 0
            self._req(bytes([block_byte(sdo.CCS_BLOCK_UPLOAD, sdo.BLOCK_START)]) + b"\x00" * 7)
        elif (
            c.state == "block_end"
            and scs == sdo.SCS_BLOCK_UPLOAD
            and sdo.block_subcommand(data[0]) == sdo.BLOCK_END
        ):
            unused = sdo.block_end_unused(data[0])
            if unused:
                del c.data[-unused:]
            crc = struct.unpack_from("<H", data, 1)[0]
            self._req(bytes([block_byte(sdo.CCS_BLOCK_UPLOAD, sdo.BLOCK_END)]) + b"\x00" * 7)
            if crc != crc16(bytes(c.data)):
                self._finish(SdoError(sdo.ABORT_CRC))
            else:
                self._finish(bytes(c.data))
        else:
            self._req(bytes([sdo.ABORT]) + mux + u32(sdo.ABORT_COMMAND))
            self._finish(SdoError(sdo.ABORT_COMMAND))

    def _down_segment(self) -> None:
        c = self.client
        chunk = bytes(c.data[c.pos : c.pos + sdo.SEGMENT_SIZE])
        c.pos += len(chunk)
        last = c.pos >= len(c.data)
        unused = sdo.SEGMENT_SIZE - len(chunk)
        head = segment_byte(sdo.CCS_DOWNLOAD_SEGMENT, c.toggle, unused, last)
        self._req(bytes([head]) + chunk.ljust(sdo.SEGMENT_SIZE, b"\x00"))

    def _block_segment(self, data: bytes) -> None:
        c = self.client
        seq, last = data[0] & sdo.SEQNO_MASK, bool(data[0] & sdo.NO_MORE_SEGMENTS)
        if seq == c.seq + 1:
            c.seq = seq
            c.data += data[1:8]
        if last or seq >= self.blksize:
            ack = block_byte(sdo.CCS_BLOCK_UPLOAD, sdo.BLOCK_ACK)
            self._req(bytes([ack, c.seq, self.blksize]) + b"\x00" * 5)
            c.seq = 0
            if last:
                c.state = "block_end"
            self._arm_timeout()
