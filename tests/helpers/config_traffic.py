"""Traffic from python-canopen in which the configuration changes while the bus runs.

A canopen LocalNode (node 5, its own heartbeat producer and SDO server) and a
RemoteNode master (canopen's SDO client and NMT master) on one python-can virtual bus,
recorded by a passive bus. Each scenario returns the frames as (t, id, data, flags)
rows and the rules file text that declares what a user would (the node's defaults);
nothing in the traffic is a fault, so `check` must find nothing. Used by the tests
(tests/checks/test_findings_trust.py) and by benchmarks/bench_precision.py.

The virtual bus runs on Python threads: periods jitter by a few ms on a busy machine,
over a hundred ms on a loaded one, so the rules text widens the absolute jitter floor
(`jitter_ms`), never the relative tolerance: what these scenarios tell apart (a gap of
250 ms against 100, of 200 ms against an event timer of 50, a 1 s silence with the
heartbeat off) stays well beyond it.
"""

from __future__ import annotations

import contextlib
import gc
import threading
import time
from collections.abc import Callable, Iterator

import can
import canopen
from canopen.objectdictionary import UNSIGNED8, UNSIGNED16, UNSIGNED32, ODRecord

from cananalyze.core.frames import FLAG_RTR
from tests.helpers.virtual_bus import drain, patient_client, unique_channel, variable

NODE = 5
# seen on a loaded 2-core machine (load 9): a first heartbeat 155 ms late
JITTER_MS = 100
RULES_HEAD = f"jitter_ms: {JITTER_MS}  # python-canopen on a virtual bus: thread scheduling\n"
Rows = list[tuple[float, int, bytes, int]]


def _od(heartbeat_ms: int) -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()
    od.add_object(variable(0x1017, 0, "Producer heartbeat time", UNSIGNED16, "rw", heartbeat_ms))
    od.add_object(variable(0x100C, 0, "Guard time", UNSIGNED16, "rw", 0))
    od.add_object(variable(0x100D, 0, "Life time factor", UNSIGNED8, "rw", 0))
    comm = ODRecord("TPDO1 communication parameter", 0x1800)
    comm.add_member(variable(0x1800, 0, "Highest sub-index", UNSIGNED8, "ro", 5))
    comm.add_member(variable(0x1800, 1, "COB-ID", UNSIGNED32, "rw", 0x180 + NODE))
    comm.add_member(variable(0x1800, 2, "Transmission type", UNSIGNED8, "rw", 255))
    comm.add_member(variable(0x1800, 5, "Event timer", UNSIGNED16, "rw", 50))
    od.add_object(comm)
    mapping = ODRecord("TPDO1 mapping parameter", 0x1A00)  # canopen's TPDO needs the pair
    mapping.add_member(variable(0x1A00, 0, "Number of mapped objects", UNSIGNED8, "rw", 1))
    mapping.add_member(variable(0x1A00, 1, "Mapped object 1", UNSIGNED32, "rw", 0x20000010))
    od.add_object(mapping)
    return od


class Bench:
    """A slave (LocalNode), a master (RemoteNode) and a recorder on one virtual channel."""

    def __init__(self, heartbeat_ms: int) -> None:
        self.channel = unique_channel("trust")
        self.slave_net, self.master_net = canopen.Network(), canopen.Network()
        self.slave_net.connect(interface="virtual", channel=self.channel)
        self.master_net.connect(interface="virtual", channel=self.channel)
        self.recorder = can.Bus(
            interface="virtual", channel=self.channel, receive_own_messages=False
        )
        self.od = _od(heartbeat_ms)
        self.local = canopen.LocalNode(NODE, self.od)
        self.slave_net.add_node(self.local)
        self.remote = patient_client(NODE)
        self.master_net.add_node(self.remote)
        self.frames: list[can.Message] = []

    def boot(self) -> None:
        """Boot-up, pre-operational with the 0x1017 in the object dictionary, started."""
        self.local.nmt.send_command(0x81)  # reset node: state 0, the boot-up message
        self.local.nmt.send_command(0x80)  # pre-operational: the heartbeat starts
        time.sleep(0.05)
        self.remote.nmt.state = "OPERATIONAL"  # canopen's NMT master: start node 5

    def write(self, index: int, sub: int, value: int, size: int) -> None:
        self.remote.sdo.download(index, sub, value.to_bytes(size, "little"))

    def read(self, index: int, sub: int) -> int:
        return int.from_bytes(self.remote.sdo.upload(index, sub), "little")

    def rows(self) -> Rows:
        self.frames += drain(self.recorder)
        return [
            (m.timestamp, m.arbitration_id, bytes(m.data), FLAG_RTR if m.is_remote_frame else 0)
            for m in self.frames
        ]

    def close(self) -> None:
        self.local.nmt.stop_heartbeat()
        self.remote.nmt.stop_node_guarding()
        self.master_net.disconnect()
        self.slave_net.disconnect()
        self.recorder.shutdown()


@contextlib.contextmanager
def bench(heartbeat_ms: int) -> Iterator[Bench]:
    """The bench while the bus runs, with the garbage collector's old objects frozen: a
    full collection of what earlier tests left (a heap of decoded logs) stalled every
    thread of the virtual bus for 300 ms, a real heartbeat gap in the recorded traffic."""
    gc.collect()
    gc.freeze()
    b = Bench(heartbeat_ms)
    try:
        yield b
    finally:
        b.close()
        gc.unfreeze()


def heartbeat_off_and_on() -> tuple[Rows, str]:
    """0x1017 100 (declared) -> 0 (no heartbeat expected) -> 300, read back."""
    with bench(100) as b:
        b.boot()
        time.sleep(0.8)
        b.write(0x1017, 0, 0, 2)
        time.sleep(1.0)
        b.write(0x1017, 0, 300, 2)
        time.sleep(1.2)
        assert b.read(0x1017, 0) == 300
        time.sleep(0.2)
        return b.rows(), RULES_HEAD + f"network:\n  nodes:\n    {NODE}: {{heartbeat_ms: 100}}\n"


def heartbeat_period_changed() -> tuple[Rows, str]:
    """Nothing declared: 250 ms learned from the log, then 0x1017 := 100 by SDO, read back."""
    with bench(250) as b:
        b.boot()
        time.sleep(2.0)
        b.write(0x1017, 0, 100, 2)
        time.sleep(1.5)
        assert b.read(0x1017, 0) == 100
        time.sleep(0.3)
        return b.rows(), RULES_HEAD


def heartbeat_to_guarding() -> tuple[Rows, str]:
    """Heartbeat 100 ms, then guarding: 0x100C := 100, 0x100D := 3, 0x1017 := 0, and
    canopen's NMT master guards the node (its replies toggle, as CiA 301 says)."""
    with bench(100) as b:
        b.boot()
        time.sleep(0.8)
        b.write(0x100C, 0, 100, 2)
        b.write(0x100D, 0, 3, 1)
        replies = _guard_replies(b)
        b.write(0x1017, 0, 0, 2)
        b.remote.nmt.start_node_guarding(0.1)
        time.sleep(1.5)
        b.remote.nmt.stop_node_guarding()
        time.sleep(0.15)  # the last request's reply
        replies()
        return b.rows(), RULES_HEAD + f"network:\n  nodes:\n    {NODE}: {{heartbeat_ms: 100}}\n"


def _guard_replies(b: Bench) -> Callable[[], None]:
    """python-canopen's LocalNode does not answer guard requests: a python-can thread
    answers for it (state byte with the toggle bit); returns the function that stops it."""
    bus = can.Bus(interface="virtual", channel=b.channel)
    done = threading.Event()

    def answer() -> None:
        toggle = 0
        while not done.is_set():
            msg = bus.recv(timeout=0.02)
            if msg is not None and msg.is_remote_frame and msg.arbitration_id == 0x700 + NODE:
                bus.send(
                    can.Message(
                        arbitration_id=0x700 + NODE, data=[0x05 | toggle], is_extended_id=False
                    )
                )
                toggle ^= 0x80

    thread = threading.Thread(target=answer, daemon=True)
    thread.start()

    def stop() -> None:
        done.set()
        thread.join()
        bus.shutdown()

    return stop


def event_timer_changed() -> tuple[Rows, str]:
    """TPDO1 (type 255) every 50 ms, its event timer 0x1800:5 := 200 by SDO: the node's
    application follows the new value (python-canopen's periodic task restarted)."""
    with bench(100) as b:
        task = {"pdo": None}

        def start(period_ms: int) -> None:
            if task["pdo"] is not None:
                task["pdo"].stop()
            task["pdo"] = b.slave_net.send_periodic(0x180 + NODE, b"\x01\x02", period_ms / 1000)

        def on_write(index, subindex, od, data):
            if (index, subindex) == (0x1800, 5):
                start(int.from_bytes(data, "little"))

        b.local.add_write_callback(on_write)
        b.boot()
        start(50)
        time.sleep(1.0)
        b.write(0x1800, 5, 200, 2)
        time.sleep(1.5)
        assert b.read(0x1800, 5) == 200
        task["pdo"].stop()
        b.remote.nmt.state = "PRE-OPERATIONAL"  # PDOs end before the node leaves operational
        time.sleep(0.2)
        net = (
            f"network:\n  nodes:\n    {NODE}:\n      heartbeat_ms: 100\n"
            "      tpdo:\n        1: {transmission_type: 255, event_timer: 50, length: 2}\n"
        )
        return b.rows(), RULES_HEAD + net


def reboot_with_defaults() -> tuple[Rows, str]:
    """0x1017 100 (declared) := 300 by SDO; the master resets the node, which boots with
    its defaults (heartbeat 100 again) and is started again."""
    with bench(100) as b:
        b.boot()
        time.sleep(0.6)
        b.write(0x1017, 0, 300, 2)
        time.sleep(1.2)
        b.local.nmt.stop_heartbeat()  # the device resets: its heartbeat task ends ...
        b.remote.nmt.send_command(0x81)  # ... on the master's NMT reset node
        b.local.data_store.pop(0x1017, None)  # and comes back with its defaults
        time.sleep(0.05)
        b.local.nmt.send_command(0x81)  # boot-up
        b.local.nmt.send_command(0x80)  # pre-operational, heartbeat 0x1017's default (100)
        time.sleep(0.1)
        b.remote.nmt.state = "OPERATIONAL"
        time.sleep(1.0)
        return b.rows(), RULES_HEAD + f"network:\n  nodes:\n    {NODE}: {{heartbeat_ms: 100}}\n"


SCENARIOS: dict[str, Callable[[], tuple[Rows, str]]] = {
    "heartbeat_off_and_on": heartbeat_off_and_on,
    "heartbeat_period_changed": heartbeat_period_changed,
    "heartbeat_to_guarding": heartbeat_to_guarding,
    "event_timer_changed": event_timer_changed,
    "reboot_with_defaults": reboot_with_defaults,
}
