"""Several buses at once: two python-can virtual buses read by one `live`, every frame
keeping its channel through the decode, the recording and the summary."""

from __future__ import annotations

import threading
import time

import can
import can.interfaces.virtual as virtual
import numpy as np
import pytest
from helpers.virtual_bus import unique_channel

from cananalyze.cli.live import buses
from cananalyze.core.errors import UsageError
from cananalyze.formats.live import LiveSource
from cananalyze.formats.live_buses import LiveBuses
from cananalyze.outputs.report.sink import ReportSink
from cananalyze.outputs.summary import SummarySink
from cananalyze.pipeline import Options, build_decoder, run


def _wait_listeners(channel: str, n: int, timeout: float = 10.0) -> None:
    """Until n buses listen on a virtual channel (the sender's own included)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with virtual.channels_lock:
            if len(virtual.channels.get(channel, [])) >= n:
                return
        time.sleep(0.01)
    raise AssertionError(f"nobody listens on {channel}")


def _send(
    channel: str,
    frames: list[can.Message],
    start: threading.Event,
    more: threading.Event | None = None,
) -> threading.Thread:
    """Send `frames` once `start` is set; with `more`, the first frame, then the rest
    once `more` is set."""

    def go():
        with can.Bus(interface="virtual", channel=channel, receive_own_messages=False) as bus:
            _wait_listeners(channel, 2)
            start.wait(10)
            for k, m in enumerate(frames):
                if k == 1 and more is not None:
                    more.wait(20)
                bus.send(m)
                time.sleep(0.0005)

    th = threading.Thread(target=go, daemon=True)
    th.start()
    return th


def _traffic(node: int, n: int) -> list[can.Message]:
    """A heartbeat and a TPDO1 per step from one node."""
    out = []
    for k in range(n):
        out.append(can.Message(arbitration_id=0x700 + node, data=[5], is_extended_id=False))
        out.append(
            can.Message(arbitration_id=0x180 + node, data=[k & 0xFF, 0, 0, 0], is_extended_id=False)
        )
    return out


def test_two_virtual_buses_keep_their_channels(tmp_path):
    a, b = unique_channel("busA"), unique_channel("busB")
    start = threading.Event()
    senders = [_send(a, _traffic(3, 150), start), _send(b, _traffic(4, 100), start)]
    parts = [
        LiveSource(lambda c=c: can.Bus(interface="virtual", channel=c), channel_name=c)
        for c in (a, b)
    ]
    source = LiveBuses(parts)
    got = []

    class Keep(SummarySink):
        def write(self, batch):
            super().write(batch)
            fb = batch.frames
            got.extend(
                (fb.channel_label(int(c)), int(i), float(t))
                for c, i, t in zip(fb.channel, fb.can_id, fb.t, strict=True)
            )

    page = tmp_path / "two.html"
    keep = Keep(None)
    report = ReportSink(page)
    opts = Options()

    def stop():
        if all(not s.is_alive() for s in senders) and source.received >= 500:
            return True
        return False

    threading.Timer(0.3, start.set).start()
    run(source, build_decoder(opts), [keep, report], opts, stop=stop, tick=0.1)
    assert len(got) == 500
    per = {}
    for ch, cid, _ in got:
        per.setdefault(ch, set()).add(cid)
    assert per == {a: {0x703, 0x183}, b: {0x704, 0x184}}  # each frame on its own bus
    for ch in (a, b):  # each bus in its own time order
        mine = [t for c, _, t in got if c == ch]
        assert mine == sorted(mine)
    # merged in time order, take by take: a reader thread the machine holds back past one
    # take (50 ms) hands in an earlier frame after a later one of the other bus
    times = [t for _, _, t in got]
    assert all(b >= a - 0.05 for a, b in zip(times, times[1:], strict=False))
    assert {k: v[0] for k, v in keep.summary.by_channel.items()} == {a: 300, b: 200}
    assert list(report.buses) == [a, b]
    assert [report.buses[a].frames, report.buses[b].frames] == [300, 200]


def test_bus_arguments():
    assert buses(["virtual"], ["a,b"]) == [("virtual", "a"), ("virtual", "b")]
    assert buses(["virtual", "socketcan"], ["a", "can1"]) == [
        ("virtual", "a"),
        ("socketcan", "can1"),
    ]
    assert buses(None, None) == [(None, None)]
    with pytest.raises(UsageError):
        buses(["virtual", "pcan", "kvaser"], ["a", "b"])


@pytest.mark.slow
def test_live_cli_two_buses_record_and_summary(tmp_path, monkeypatch, capsys):
    """`live -i virtual -c A,B --record x.log --plain`: the candump recording names both
    buses, as python-can's reader reads them back."""
    from cananalyze.cli.main import main

    a, b = unique_channel("cliA"), unique_channel("cliB")
    start = threading.Event()
    senders = [_send(a, _traffic(3, 60), start), _send(b, _traffic(4, 40), start)]
    rec = tmp_path / "two.log"

    def go():
        for c in (a, b):
            _wait_listeners(c, 2)
        start.set()
        for s in senders:
            s.join(10)

    threading.Thread(target=go, daemon=True).start()
    code = main(
        ["live", "-i", "virtual", "-c", f"{a},{b}", "--plain", "--record", str(rec)]
        + ["--duration", "4"]
    )
    out = capsys.readouterr().out
    assert code == 0
    with can.LogReader(str(rec)) as reader:
        msgs = list(reader)
    per = {}
    for m in msgs:
        per[m.channel] = per.get(m.channel, 0) + 1
    assert per == {a: 120, b: 80}
    assert "frames per channel:" in out
    assert f"{a[:15]}" in out


def test_dashboard_shows_each_bus():
    """Two channels in the batches: the dashboard's head names each with its frames and load
    (frames counted here from the batch independently, load from nominal bits)."""
    from rich.console import Console

    from cananalyze.core.frames import from_rows
    from cananalyze.outputs.dashboard import LiveView
    from cananalyze.pipeline import Decoder

    rows = [(1.0 + k * 0.01, 0x701, b"\x05", 0, k % 3 == 0) for k in range(90)]
    fb = from_rows(rows, channels=("can0", "can1"))
    view = LiveView(bitrate=125_000)
    view.add(Decoder().decode(fb), wall=10.0)
    console = Console(record=True, width=160, color_system=None)
    console.print(view.render(wall=10.0, height=30))
    text = console.export_text()
    per = np.bincount(fb.channel)
    # 47 + 8 bits per frame over the log's 0.89 s at 125 kbit/s
    load = [f"{n * 55 / (125_000 * 0.89) * 100:.1f} %" for n in per]
    assert f"can0: {per[0]} frames, {load[0]} load" in text
    assert f"can1: {per[1]} frames, {load[1]} load" in text


@pytest.mark.slow  # a live session in real time: in CI's one-process slow run
def test_two_buses_live_in_foxglove_apart():
    """`live -c A,B --foxglove`: a WebSocket client on 127.0.0.1 gets every frame of both
    buses on /can/frames with its channel, and each bus's PDO signals on its own topic."""
    pytest.importorskip("foxglove")
    pytest.importorskip("websockets")
    from helpers.foxglove_client import FoxgloveClient

    from cananalyze.core.records import on_bus
    from cananalyze.outputs.foxglove.sink import FoxgloveSink

    a, b = unique_channel("foxA"), unique_channel("foxB")
    start = threading.Event()

    def tpdo2(node: int, n: int) -> list[can.Message]:
        return [
            can.Message(
                arbitration_id=0x280 + node, data=bytes([k & 0xFF, 0] * 4), is_extended_id=False
            )
            for k in range(n)
        ]

    # one PDO per bus first (it advertises the bus's signal topic), the rest once the
    # client has subscribed to both: else, on a loaded machine, every PDO could pass
    # before the subscription and the topic stay empty
    more = threading.Event()
    topics = {on_bus(a, "/node/5/tpdo2"), on_bus(b, "/node/5/tpdo2")}
    senders = [
        _send(a, tpdo2(5, 300), start, more),
        _send(b, tpdo2(5, 200), start, more),
    ]
    parts = [
        LiveSource(lambda c=c: can.Bus(interface="virtual", channel=c), channel_name=c)
        for c in (a, b)
    ]
    source = LiveBuses(parts)
    fox = FoxgloveSink(port=0, announce=False)
    box: list = []

    class Client(SummarySink):  # opened after the server: the client connects, then traffic
        def open(self, run):
            super().open(run)
            client = FoxgloveClient(fox.url).start()
            box.append(client)
            deadline = time.monotonic() + 10
            while "/can/frames" not in client.topics_subscribed() and time.monotonic() < deadline:
                time.sleep(0.02)
            time.sleep(0.3)  # the server handles the subscription
            start.set()

    opts = Options(devices={5: "dat7014"})

    deadline = time.monotonic() + 30

    def stop():  # once the client has every frame (the server stops with the run)
        if time.monotonic() > deadline:
            return True
        # the server's word that the client subscribed (a subscription it refused, seen
        # in parallel runs: "subscribe to unknown channel", would hold the senders)
        if all(fox._watched(t) for t in topics):
            more.set()
        sent = all(not s.is_alive() for s in senders) and source.received >= 500
        return sent and len(box[0].messages.get("/can/frames", [])) >= 500

    run(source, build_decoder(opts), [fox, Client(None)], opts, stop=stop, tick=0.1)
    client = box[0]
    client.stop()
    assert client.error is None
    frames = client.messages["/can/frames"]
    per = {}
    for _, m in frames:
        per[m["channel"]] = per.get(m["channel"], 0) + 1
    assert per == {a: 300, b: 200}
    # node 5 on each bus: its own signal topic (the later messages: it was advertised
    # with its first PDO, the client subscribed then)
    for ch, n in ((a, 300), (b, 200)):
        got = client.messages.get(on_bus(ch, "/node/5/tpdo2"), [])
        assert 0 < len(got) <= n
        assert len(got) >= n - 100, (ch, len(got))
    assert "/node/5/tpdo2" not in client.topics_subscribed()
