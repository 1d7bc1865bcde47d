"""Several buses in MCAP and Foxglove: each bus's decoded topics apart (/can1/node/5/tpdo2),
every frame on /can/frames with its channel. Read back with mcap's reader, python-can's
log reader and a Foxglove WebSocket client on 127.0.0.1."""

from __future__ import annotations

import json

import can
import pytest
from conftest import SAMPLES

from cananalyze.formats.source import open_log, read_all
from cananalyze.outputs.mcap.sink import McapSink
from cananalyze.pipeline import Options, build_decoder, run
from tests.outputs.test_foxglove_live import Halves, _mcap_messages


@pytest.fixture
def two_buses(tmp_path):
    """faults.log with node 3's heartbeats moved to can1 and a second node 5 on can1: every
    frame to or from node 5 (its SDO configuration too) also on can1, as its own device."""
    out = []
    for line in (SAMPLES / "faults.log").read_text().splitlines():
        if " can0 703#" in line:
            line = line.replace(" can0 ", " can1 ")
        out.append(line)
        cob = line.split(" can0 ")[1].split("#")[0] if " can0 " in line else ""
        if len(cob) == 3 and int(cob, 16) & 0x7F == 5 and int(cob, 16) >= 0x80:
            out.append(line.replace(" can0 ", " can1 "))
    path = tmp_path / "two.log"
    path.write_text("\n".join(out) + "\n")
    return path


def _pycan(path) -> list[can.Message]:
    with can.LogReader(str(path)) as reader:
        return list(reader)


def _ns(t: float) -> int:
    return int(round(t * 1e9))


def _us(t: float) -> int:
    """µs of a float time (the log's resolution; ns of a float epoch time are not exact)."""
    return int(round(t * 1e6))


def _export(log, mcap) -> dict[str, list]:
    opts = Options(network=SAMPLES / "network.toml")
    run(open_log(log), build_decoder(opts), [McapSink(mcap)], opts)
    return _mcap_messages(mcap)


def test_mcap_topics_separate_the_buses(two_buses, tmp_path):
    two = _export(two_buses, tmp_path / "two.mcap")
    one = _export(SAMPLES / "faults.log", tmp_path / "one.mcap")  # the same frames on one bus
    msgs = _pycan(two_buses)
    per_bus = {
        ch: [_us(m.timestamp) for m in msgs if m.arbitration_id == 0x285 and m.channel == ch]
        for ch in ("can0", "can1")
    }
    assert all(per_bus.values())
    assert "/node/5/tpdo2" in one and "/node/5/tpdo2" not in two
    for ch, times in per_bus.items():
        assert [round(t / 1e3) for t, _ in two[f"/{ch}/node/5/tpdo2"]] == times
    # each node 5 decodes as the one-bus log's node 5, on its own bus
    assert two["/can0/node/5/tpdo2"] == two["/can1/node/5/tpdo2"] == one["/node/5/tpdo2"]
    # node 3's states come from its heartbeats, all on can1
    assert "/can1/node/3/nmt_state" in two and "/can0/node/3/nmt_state" not in two
    assert [m for _, m in two["/can1/node/3/nmt_state"]] == [m for _, m in one["/node/3/nmt_state"]]
    # every frame on the one frames topic, each with its own channel
    frames = two["/can/frames"]
    assert [m["channel"] for _, m in frames] == [m.channel for m in msgs]
    assert {m["name"] for _, m in two["/canopen/events"]} & {"can1 node 3", "can0 node 5"}


def test_one_bus_keeps_its_topics(tmp_path):
    """A log of one channel: no bus in the topic names (layouts made before keep working)."""
    topics = set(_export(SAMPLES / "faults.log", tmp_path / "x.mcap"))
    assert {"/node/5/tpdo2", "/node/3/nmt_state", "/can/frames"} <= topics
    assert not any(t.startswith("/can0/") for t in topics)


def test_foxglove_client_gets_the_buses_apart(two_buses, tmp_path):
    pytest.importorskip("foxglove")
    pytest.importorskip("websockets")
    from cananalyze.outputs.foxglove.sink import FoxgloveSink

    opts = Options(network=SAMPLES / "network.toml")
    fb = read_all(two_buses)
    fox = FoxgloveSink(port=0, announce=False)
    box: list = []
    source = Halves(fb, fox, box)
    mcap = tmp_path / "x.mcap"
    run(source, build_decoder(opts), [fox, McapSink(mcap)], opts)
    client = box[0]
    client.stop()
    assert client.error is None
    written = _mcap_messages(mcap)
    t_split = _ns(fb.t[source.split])
    for topic in ("/can0/node/5/tpdo2", "/can1/node/5/tpdo2"):
        late = [(t, json.dumps(m)) for t, m in written[topic] if t >= t_split]
        got = [(t, json.dumps(m)) for t, m in client.messages.get(topic, [])]
        assert late and got == late, topic
    assert "/node/5/tpdo2" not in client.topics_subscribed()


def test_same_node_id_on_two_buses_is_two_devices(tmp_path):
    """Two nodes 5, each beating every 100 ms on its own bus: no heartbeat finding and
    one NMT state each (before each bus had its decoder: their heartbeats merged, a 1 ms
    'period', 49 dropouts, the state flapping between the two nodes' states)."""
    from cananalyze import check

    lines = []
    for k in range(50):
        t = 1000.0 + k * 0.1
        lines += [f"({t:.6f}) can0 705#05", f"({t + 0.001:.6f}) can1 705#7F"]
    log = tmp_path / "two5.log"
    log.write_text("\n".join(lines) + "\n")
    found = check(str(log))
    assert [f for f in found if f.rule == "heartbeat"] == []
