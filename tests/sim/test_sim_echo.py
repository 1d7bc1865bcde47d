"""The real-time simulator sends each frame once: on a bus that hands its own frames back
(udp_multicast does) they reach the simulated participants once, not again as echo; and an
event run late (real time under load) does not send a TPDO twice."""

from __future__ import annotations

import heapq
import threading

import can
from helpers.virtual_bus import unique_channel

from cananalyze.core.frames import FLAG_RTR
from cananalyze.sim.engine import START, OwnEcho, Simulation, bus_echoes_own_frames
from cananalyze.sim.session import build


def test_own_echo_drops_each_sent_frame_once():
    echo = OwnEcho(max_age=2.0)
    echo.sent(0x707, b"", FLAG_RTR, now=1.0)
    echo.sent(0x080, b"", 0, now=1.0)
    echo.sent(0x080, b"", 0, now=1.1)
    assert not echo.is_echo(0x707, b"", 0, now=1.2)  # a data frame is not the RTR sent
    assert echo.is_echo(0x707, b"", FLAG_RTR, now=1.2)
    assert not echo.is_echo(0x707, b"", FLAG_RTR, now=1.2)  # one echo per frame sent
    assert echo.is_echo(0x080, b"", 0, now=1.3) and echo.is_echo(0x080, b"", 0, now=1.3)
    assert not echo.is_echo(0x080, b"", 0, now=1.3)  # a third SYNC came from someone else
    echo.sent(0x185, b"\x01", 0, now=2.0)
    assert not echo.is_echo(0x185, b"\x01", 0, now=4.5)  # not back in 2 s: given up
    assert echo.dropped == 3


def test_udp_multicast_is_the_bus_that_echoes():
    bus = can.Bus(interface="virtual", channel=unique_channel("echo-kind"))
    try:
        assert not bus_echoes_own_frames(bus)
    finally:
        bus.shutdown()
    # the class is named, not opened: opening one would touch the network
    from can.interfaces.udp_multicast import UdpMulticastBus

    assert bus_echoes_own_frames(UdpMulticastBus.__new__(UdpMulticastBus))


def test_guard_requests_answered_once_on_an_echoing_bus():
    """A virtual bus with receive_own_messages echoes as udp_multicast does, in-process."""
    channel = unique_channel("echo")
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=True)
    listener = can.Bus(interface="virtual", channel=channel)
    sim, _, _ = build(duration=1.5)
    try:
        runner = threading.Thread(target=sim.run_realtime, args=(bus, 1.5), kwargs={"echoes": True})
        runner.start()
        runner.join(timeout=60)
        assert not runner.is_alive()
        seen = []
        while (msg := listener.recv(timeout=0)) is not None:
            seen.append(msg)
    finally:
        bus.shutdown()
        listener.shutdown()
    requests = [m for m in seen if m.arbitration_id == 0x707 and m.is_remote_frame]
    first = seen.index(requests[0])
    replies = [m for m in seen[first:] if m.arbitration_id == 0x707 and not m.is_remote_frame]
    assert len(requests) >= 3
    assert len(requests) - len(replies) in (0, 1)  # the last may have been cut by the end
    # every echo was recognised as one, and nothing else was dropped
    assert sim.echo is not None and sim.echo.dropped == len(seen)
    # strictly request, reply, request, reply: never two replies to one request
    kinds = [m.is_remote_frame for m in seen[first:] if m.arbitration_id == 0x707]
    assert all(a != b for a, b in zip(kinds, kinds[1:], strict=False))


class _LateSimulation(Simulation):
    """Offline, but every event runs `LAG` after its time, as in a loaded real-time loop
    (there `now` is the clock when the loop gets to an event, not the event's time)."""

    LAG = 0.004

    def run(self, duration: float) -> None:
        for p in self.participants:
            p.start(self)
        while self._queue and self._queue[0][0] <= duration:
            t, _, fn = heapq.heappop(self._queue)
            self.now = max(self.now, t + self.LAG)
            fn()


def test_a_late_scan_does_not_send_a_tpdo_its_inhibit_time_holds_back():
    """A scan due just before the inhibit time ends, run just after it, sent the TPDO and
    the send held back for that moment sent it again 0.3 ms later (seen in real time)."""
    sim, _, _ = build(scenario="commissioning", duration=8.0)
    sim.__class__ = _LateSimulation
    sim.run(8.0)
    # node 3's TPDO2 (0x283): inhibit time 100 ms from the configuration at ~0.4 s on
    sent = [t for t, cob, _, _ in sim.rows if cob == 0x283 and t - START > 1.0]
    gaps = [b - a for a, b in zip(sent, sent[1:], strict=False)]
    assert len(sent) > 20
    assert min(gaps) >= 0.1 - 1e-6, sorted(gaps)[:3]
