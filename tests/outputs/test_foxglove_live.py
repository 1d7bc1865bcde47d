"""`live --foxglove`: a Foxglove WebSocket client on 127.0.0.1 subscribes and receives the
decode, message for message what `export --mcap` writes (read back with mcap's reader)."""

from __future__ import annotations

import json
import signal
import socket
import time

import numpy as np
import pytest
from conftest import SAMPLES
from helpers.foxglove_client import FoxgloveClient

from cananalyze.core.errors import ProblemLog, UsageError
from cananalyze.core.frames import FrameBatch
from cananalyze.formats.source import read_all
from cananalyze.outputs.foxglove.sink import END_TOPIC, FoxgloveSink, parse_address
from cananalyze.outputs.mcap.sink import McapSink
from cananalyze.pipeline import Options, build_decoder, run

pytest.importorskip("foxglove")
pytest.importorskip("websockets")


def _mcap_messages(path) -> dict[str, list[tuple[int, dict]]]:
    from mcap.reader import make_reader

    out: dict[str, list] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data)))
    return out


class Halves:
    """A source: the first half of a log, then (once the client has subscribed to every
    channel the server advertised) the second half."""

    def __init__(self, fb: FrameBatch, sink: FoxgloveSink, client_box: list) -> None:
        self.fb, self.sink, self.box = fb, sink, client_box
        self.path = "faults.log"
        self.problems = ProblemLog()
        self.split = len(fb) // 2

    def batches(self):
        yield self.fb.take(np.arange(self.split))
        deadline = time.monotonic() + 20
        # the pipeline reads ahead: wait until the sink has served the first half
        while not self.sink.served and time.monotonic() < deadline:
            time.sleep(0.01)
        client = FoxgloveClient(self.sink.url).start()
        self.box.append(client)
        while time.monotonic() < deadline:
            if len(client.subscribed) == len(self.sink._channels) and all(
                ch.has_sinks() for ch in self.sink._channels.values()
            ):
                break
            time.sleep(0.02)
        yield self.fb.take(np.arange(self.split, len(self.fb)))
        client.wait_for("/can/frames", len(self.fb) - self.split)


def test_client_receives_what_export_mcap_writes(tmp_path):
    opts = Options(network=SAMPLES / "network.toml", rules=SAMPLES / "rules.yaml")
    fb = read_all(SAMPLES / "faults.log")
    fox = FoxgloveSink(port=0, announce=False)
    box: list = []
    source = Halves(fb, fox, box)
    mcap = tmp_path / "x.mcap"
    run(source, build_decoder(opts), [fox, McapSink(mcap)], opts)
    client = box[0]
    client.stop()
    assert client.error is None
    assert client.server_info["name"] == "cananalyze"
    written = _mcap_messages(mcap)
    t_split = int(round(fb.t[source.split] * 1e9))
    # every topic advertised by the end of the first half, message for message
    topics = client.topics_subscribed()
    assert {"/can/frames", "/canopen/events", "/node/5/tpdo2", "/node/3/tpdo2"} <= topics
    # live only: the server's last message, after which the client left with everything
    (end,) = client.messages.pop(END_TOPIC)
    assert end[1]["message"] == f"live decode ended: {fox.sent - 1} messages served"
    assert end[0] == int(round(fb.t[-1] * 1e9))  # on the log's clock, as every message
    assert fox.sent == sum(map(len, client.messages.values())) + 1
    topics.discard(END_TOPIC)
    key = lambda tm: (tm[0], json.dumps(tm[1], sort_keys=True))  # noqa: E731
    for topic in topics:
        got = sorted(map(key, client.messages.get(topic, [])))
        every = sorted(map(key, written.get(topic, [])))
        # what the second half made, and (events) what the end of the log found earlier
        late = [k for k in every if k[0] >= t_split]
        assert set(got) <= set(every) and set(late) <= set(got), topic
        assert len(got) == len(set(got)), topic
    assert len(client.messages["/can/frames"]) == len(fb) - source.split
    # schemas as the MCAP file has them
    adv = {c["topic"]: c for c in client.channels.values()}
    assert adv["/canopen/events"]["schemaName"] == "foxglove.Log"
    assert json.loads(adv["/node/5/tpdo2"]["schema"])["properties"]["ch1"] == {
        "type": "number",
        "description": "unit: °C",
    }
    assert any("sdo" in m["message"].lower() for _, m in client.messages["/canopen/events"])


def test_address_parsing_and_loopback_default():
    assert parse_address(None) == ("127.0.0.1", 8765)
    assert parse_address("9000") == ("127.0.0.1", 9000)
    assert parse_address(":9001") == ("127.0.0.1", 9001)
    assert parse_address("127.0.0.1:0") == ("127.0.0.1", 0)
    with pytest.raises(UsageError):
        parse_address("127.0.0.1:http")
    with pytest.raises(UsageError):
        parse_address("127.0.0.1:70000")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_live_cli_serves_and_records_at_once(tmp_path):
    """`live --record x.mcap --foxglove 127.0.0.1:PORT` on an slcan pty: the client gets
    every frame, and the recording has the same ones."""
    from helpers.live_slcan import start_live

    from cananalyze.sim.slcan_replay import replay

    port = _free_port()
    rec = tmp_path / "live.mcap"
    proc, adapter, _ = start_live(
        ["--plain", "--record", str(rec), "--foxglove", f"127.0.0.1:{port}"]
    )
    try:
        client = FoxgloveClient(f"ws://127.0.0.1:{port}").start()
        deadline = time.monotonic() + 10
        while "/can/frames" not in client.topics_subscribed() and time.monotonic() < deadline:
            time.sleep(0.02)
        time.sleep(0.3)  # the server handles the subscription
        sent = replay(adapter, str(SAMPLES / "demo.log"), timed=False)
        assert client.wait_for("/can/frames", sent, timeout=20)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        client.stop()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert f"foxglove: serving ws://127.0.0.1:{port}" in err
    got = client.messages["/can/frames"]
    recorded = read_all(rec)
    assert len(got) == sent == len(recorded)
    assert [m["can_id"] for _, m in got] == recorded.can_id.tolist()
    assert [m["data"] for _, m in got] == [
        bytes(recorded.payload(i)).hex() for i in range(len(recorded))
    ]
    assert any(m["service"] == "sdo_response" for _, m in got)


def test_port_in_use_is_one_line(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        sink = FoxgloveSink(port=port, announce=False)
        opts = Options()
        with pytest.raises(UsageError, match=f"127.0.0.1:{port}: cannot listen"):
            run(read_source(), build_decoder(opts), [sink], opts)


def read_source():
    from cananalyze.pipeline import MemorySource

    return MemorySource(read_all(SAMPLES / "demo.log"))


def test_client_receives_the_drive_state_lane(tmp_path):
    """A CiA 402 drive's states reach the client on `/node/N/drive_state`, as in MCAP."""
    words = [0x0250, 0x0231, 0x0233, 0x0237, 0x0218, 0x0250, 0x0231, 0x0233, 0x0237]
    log = tmp_path / "drive.log"
    log.write_text(
        "".join(
            f"({1.0 + k * 0.01:.6f}) can0 18B#{w & 0xFF:02X}{w >> 8:02X}\n"
            for k, w in enumerate(words * 4)
        )
    )
    opts = Options(devices={11: "cia402"})
    fb = read_all(log)
    fox = FoxgloveSink(port=0, announce=False)
    box: list = []
    source = Halves(fb, fox, box)
    mcap = tmp_path / "x.mcap"
    run(source, build_decoder(opts), [fox, McapSink(mcap)], opts)
    client = box[0]
    client.stop()
    assert client.error is None
    written = _mcap_messages(mcap)["/node/11/drive_state"]
    t_split = int(round(fb.t[source.split] * 1e9))
    got = client.messages["/node/11/drive_state"]
    assert got == [m for m in written if m[0] >= t_split] != []
    assert {m["state"] for _, m in got} >= {"operation enabled", "fault"}


def test_unwatched_topics_cost_no_payloads(monkeypatch):
    """With no client subscribed, the sink advertises the topics but builds no message:
    frame documents (the bulk of a live bus) are not serialised for nobody."""
    import cananalyze.outputs.mcap.stream as stream

    built: list[int] = []
    real = stream.frame_payloads
    monkeypatch.setattr(
        stream, "frame_payloads", lambda fb, *a: built.append(len(fb)) or real(fb, *a)
    )
    opts = Options(network=SAMPLES / "network.toml")
    fox = FoxgloveSink(port=0, announce=False)
    run(read_source(), build_decoder(opts), [fox], opts)
    assert fox.served > 0 and fox.sent == 0 and built == []
    assert {"/can/frames", "/canopen/events", "/node/5/tpdo2"} <= set(fox._channels)
    # an MCAP export of the same log still builds every frame's document
    import tempfile

    from cananalyze.outputs.mcap.sink import McapSink as Mcap

    with tempfile.TemporaryDirectory() as d:
        run(read_source(), build_decoder(opts), [Mcap(f"{d}/x.mcap")], opts)
    assert sum(built) == len(read_all(SAMPLES / "demo.log"))
