"""The simulation clock and bus: a discrete-event queue, or real time on a python-can bus.

Offline (`--to FILE`) the clock jumps from event to event, so ten minutes of
traffic take a moment and a seed gives the same frames every time. Frames are
serialized on the simulated bus (one after the other, each taking its time at
the bit rate) and delivered to the other participants when they end. In real
time the same participants run against `time.monotonic()` and a python-can bus.
"""

from __future__ import annotations

import heapq
import itertools
import time
from collections import deque
from collections.abc import Callable
from typing import Protocol

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR, FLAG_TX, FrameBatch, from_rows

START = 1767225600.0  # 2026-01-01T00:00:00Z: the simulated wall clock of offline logs


class Participant(Protocol):
    def start(self, sim: Simulation) -> None: ...

    def on_frame(self, cob: int, data: bytes, flags: int) -> None: ...


def frame_seconds(dlc: int, bitrate: int) -> float:
    """Worst-case duration of a classic 11-bit frame with stuff bits."""
    return (47 + 8 * dlc) * 1.2 / bitrate


def bus_echoes_own_frames(bus: object) -> bool:
    """Whether `bus.recv()` also returns the frames this process sent on `bus`.

    python-can's udp_multicast bus does: IP multicast loopback is how two processes on one
    host hear each other, and it hands the sender its own datagrams too (the bus's
    `receive_own_messages=False` is not honoured). socketcan, virtual and the adapters
    return only the others' frames unless asked to."""
    return type(bus).__name__ == "UdpMulticastBus"


class OwnEcho:
    """The frames this process sent that its bus has not handed back yet.

    The simulator delivers its frames to its own participants when it sends them; a bus
    that echoes them would deliver each a second time (a guard request answered twice,
    a SYNC counted twice). A received frame equal to one still awaited is that echo and
    is dropped. Were another process to send an equal frame meanwhile, one of the two
    is dropped either way: they cannot be told apart, and the count stays right. An echo
    not back within `max_age` seconds is given up, so a lost one cannot swallow later
    frames for long."""

    def __init__(self, max_age: float = 2.0) -> None:
        self.max_age = max_age
        self._awaited: dict[tuple[int, int, bytes], deque[float]] = {}
        self.dropped = 0

    def sent(self, cob: int, data: bytes, flags: int, now: float) -> None:
        self._awaited.setdefault((cob, flags, data), deque()).append(now)

    def is_echo(self, cob: int, data: bytes, flags: int, now: float) -> bool:
        """True (and forgotten) if this frame is the echo of one this process sent."""
        key = (cob, flags, data)
        times = self._awaited.get(key)
        while times and now - times[0] > self.max_age:
            times.popleft()
        if not times:
            self._awaited.pop(key, None)
            return False
        times.popleft()
        self.dropped += 1
        return True


class Simulation:
    """Event queue plus bus; participants schedule callbacks and send frames."""

    def __init__(self, bitrate: int = 500_000, start: float = START):
        self.now = 0.0  # seconds since the start of the simulation
        self.start_time = start
        self.bitrate = bitrate
        self.participants: list[Participant] = []
        self.rows: list[tuple[float, int, bytes, int]] = []
        self._queue: list[tuple[float, int, Callable[[], None]]] = []
        self._seq = itertools.count()
        self._bus_free = 0.0
        self.bus = None  # python-can bus in real-time mode
        self._t0 = 0.0
        self._stopped = False
        self.echo: OwnEcho | None = None  # real time on a bus that echoes what we send

    def stop(self) -> None:
        """End a real-time run early (safe to call from another thread)."""
        self._stopped = True

    def add(self, participant: Participant) -> Participant:
        self.participants.append(participant)
        return participant

    def at(self, t: float, fn: Callable[[], None]) -> None:
        heapq.heappush(self._queue, (t, next(self._seq), fn))

    def after(self, dt: float, fn: Callable[[], None]) -> None:
        self.at(self.now + dt, fn)

    def send(self, sender: object, cob: int, data: bytes = b"", flags: int = 0) -> float:
        """Put a frame on the bus now; the others receive it when it has been transmitted.

        Returns when the frame started: later than now when the bus was busy.
        """
        data = bytes(data)
        if self.bus is not None:
            self._send_real(cob, data, flags)
            t = t_end = self.now
        else:
            t = max(self.now, self._bus_free)
            t_end = t + frame_seconds(len(data), self.bitrate)
            self._bus_free = t_end
            self.rows.append((self.start_time + round(t, 6), cob, data, flags))
        if not flags & FLAG_ERR:
            for p in self.participants:
                if p is not sender:
                    self.at(t_end, lambda p=p: p.on_frame(cob, data, flags))
        return t

    def run(self, duration: float) -> None:
        """Offline: process events up to duration seconds."""
        for p in self.participants:
            p.start(self)
        while self._queue and self._queue[0][0] <= duration:
            t, _, fn = heapq.heappop(self._queue)
            self.now = max(self.now, t)
            fn()
        self.now = duration

    def batch(self) -> FrameBatch:
        rows = sorted(self.rows, key=lambda r: r[0])
        return from_rows(rows, channels=("can0",))

    # --- real time ------------------------------------------------------------------
    def run_realtime(self, bus, duration: float, echoes: bool | None = None) -> None:
        """Run against a python-can bus until duration seconds have passed.

        `echoes`: the bus returns this process's own frames (default: asked of
        `bus_echoes_own_frames`); those are dropped, each frame is delivered once."""
        self.bus = bus
        if echoes if echoes is not None else bus_echoes_own_frames(bus):
            self.echo = OwnEcho()
        self._t0 = time.monotonic()
        for p in self.participants:
            p.start(self)
        while True:
            self.now = time.monotonic() - self._t0
            if self.now >= duration or self._stopped:
                break
            while self._queue and self._queue[0][0] <= self.now:
                _, _, fn = heapq.heappop(self._queue)
                fn()
            nxt = self._queue[0][0] if self._queue else duration
            timeout = max(0.0, min(nxt, duration) - (time.monotonic() - self._t0))
            msg = bus.recv(timeout=min(timeout, 0.05))
            if msg is None or msg.is_error_frame:
                continue
            self.now = time.monotonic() - self._t0
            flags = _flags(msg)
            data = b"" if msg.is_remote_frame else bytes(msg.data)
            if self.echo is not None and self.echo.is_echo(
                msg.arbitration_id, data, flags, self.now
            ):
                continue  # delivered when it was sent
            for p in self.participants:
                p.on_frame(msg.arbitration_id, data, flags)

    def _send_real(self, cob: int, data: bytes, flags: int) -> None:
        import can

        msg = can.Message(
            arbitration_id=cob,
            data=data if not flags & FLAG_RTR else None,
            dlc=len(data) if not flags & FLAG_RTR else 0,
            is_extended_id=bool(flags & FLAG_EXT),
            is_remote_frame=bool(flags & FLAG_RTR),
            is_error_frame=bool(flags & FLAG_ERR),
        )
        try:
            self.bus.send(msg)
        except can.CanError:
            return  # a full transmit queue drops the frame, as a real controller would
        if self.echo is not None:
            self.echo.sent(cob, b"" if msg.is_remote_frame else data, _flags(msg), self.now)


def _flags(msg) -> int:
    """The flags a received frame is compared and delivered with (RTR, extended)."""
    return (FLAG_RTR if msg.is_remote_frame else 0) | (FLAG_EXT if msg.is_extended_id else 0)


__all__ = [
    "FLAG_TX",
    "START",
    "OwnEcho",
    "Participant",
    "Simulation",
    "bus_echoes_own_frames",
    "frame_seconds",
]
