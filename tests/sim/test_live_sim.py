"""The simulator as the traffic producer: the faults scenario runs in real time on a
python-can virtual bus (in a thread: the virtual bus is in-process only) while a
LiveSource on the same channel feeds the real decoder and the Checker; the faults
the scenario injects must be found live, as `check` finds them in the recorded sample."""

from __future__ import annotations

import threading
import time

import can
import pytest
from conftest import SAMPLES

from cananalyze.checks.build import build_checker
from cananalyze.formats.live import LiveSource
from cananalyze.outputs.dashboard import LiveView
from cananalyze.pipeline import Options, build_decoder
from cananalyze.sim.network import load_network
from cananalyze.sim.session import build

NETWORK = SAMPLES / "network.toml"


@pytest.mark.slow
def test_simulated_faults_are_found_live():
    net = load_network(str(NETWORK))
    sim, _, _ = build(net.profiles, "faults", 10.5, 0, net.bitrate, config=net.config)
    channel = f"cananalyze-live-sim-{time.monotonic_ns()}"
    sim_bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    source = LiveSource(can.Bus(interface="virtual", channel=channel), channel_name="vcan0")
    checker = build_checker(SAMPLES / "rules.yaml")
    dec = build_decoder(Options(network=NETWORK), checker)
    view = LiveView(bitrate=net.bitrate, model=dec.network, checking=True)

    def produce():
        try:
            sim.run_realtime(sim_bus, 10.5)
        finally:
            time.sleep(0.3)
            source.stop()

    producer = threading.Thread(target=produce, daemon=True)
    source.start()  # listening before the first boot-up
    producer.start()
    seen_while_running: set[tuple[str, int | None]] = set()
    for fb in source.batches():
        view.add(dec.decode(fb))
        if producer.is_alive():
            seen_while_running |= {(f.rule, f.node) for f in checker.findings}
    view.add(dec.finish())
    producer.join(5)
    sim_bus.shutdown()

    got = {(f.rule, f.node) for f in checker.findings}
    faults = {
        ("emcy", 3),  # MCB-560 EMCYs
        ("emcy", 7),  # I-7231D device-specific EMCY, never reset
        ("assert_signal", 5),  # DAT 7014 ch3 open circuit 3276.7 degC
        ("heartbeat", 6),  # DAT 7130 heartbeat dropout
        ("pdo_async", 3),  # MCB-560 inhibit time and event timer
        ("sdo", 3),  # abort: object does not exist
        ("sdo", 5),  # abort: read-only object; 0x1008 read unanswered
    }
    assert faults <= got, sorted(got)
    # found as the session ran, not only at the end
    assert faults - {("emcy", 7)} <= seen_while_running
    msgs = {f.message for f in checker.findings if f.rule == "sdo"}
    assert "SDO download 0x1018:01 abort: Attempt to write a read only object" in msgs
    assert "SDO upload 0x2FFF:00 abort: Object does not exist in the object dictionary" in msgs
    # the dashboard saw the same: devices from the network file, the findings counted
    assert view.violations == sum(f.fails for f in checker.findings)
    assert view.device(5).startswith("Datexel DAT 7014")
    assert {k[:2] for k in view.signals} >= {(5, "tpdo2"), (3, "tpdo2"), (6, "tpdo1")}
    assert view.nodes[6].state == "operational"
