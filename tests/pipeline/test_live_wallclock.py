"""Live deadlines on the wall clock: python-canopen's heartbeat producer on python-can's
virtual bus, the only node there, falls silent and no frame arrives at all. The
finding must come while the session runs, within the period x (1 + tolerance) + 0.5 s,
once (also when the node then comes back late), and say that no frame came from any
node (the adapter or the logger may have stopped). An SDO request nobody answers is a
timeout on the tick too. A log file that ends is no silence.

Real time on a shared machine: margins survive a load of 10 (the jitter floor covers a
virtual-bus thread's scheduling), and the finding must precede the stop, whatever the
load adds.
"""

from __future__ import annotations

import io
import threading
import time

import can
import canopen
import pytest
from canopen.objectdictionary import UNSIGNED16
from canopen.sdo.exceptions import SdoError
from rich.console import Console

from cananalyze.core.frames import from_rows
from cananalyze.formats.live import LiveSource
from cananalyze.outputs.dashboard import DashboardSink
from cananalyze.pipeline import MemorySource, Options, build_checker, build_decoder, run
from cananalyze.pipeline.sink import Sink
from tests.helpers.virtual_bus import unique_channel, variable

NODE = 5
PERIOD_MS = 100
JITTER_MS = 150  # the rules file's floor: a virtual bus's threads on a loaded machine
BOUND_S = (PERIOD_MS + max(PERIOD_MS * 0.1, JITTER_MS)) / 1000 + 0.5


class _Findings(Sink):
    """Every finding the pipeline delivers, with the wall time it came."""

    def __init__(self) -> None:
        self.got: list[tuple[float, object]] = []

    def write(self, batch) -> None:
        now = time.monotonic()
        self.got.extend((now, f) for f in batch.findings)


def _rules(tmp_path, text: str = ""):
    path = tmp_path / "rules.yaml"
    path.write_text(
        f"jitter_ms: {JITTER_MS}\nnetwork:\n  nodes:\n    {NODE}: {{heartbeat_ms: {PERIOD_MS}}}\n"
        + text
    )
    return path


class _Session:
    """`live --check` in-process: pipeline.run over a LiveSource on its own thread."""

    def __init__(self, channel: str, rules, sdo_timeout: float = 1.0, sinks=()) -> None:
        self.opts = Options(rules=rules, checks=True, sdo_timeout=sdo_timeout)
        self.decoder = build_decoder(self.opts, build_checker(self.opts))
        self.sink = _Findings()
        self.sinks = [self.sink, *sinks]
        self.source = LiveSource(can.Bus(interface="virtual", channel=channel))
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            run(self.source, self.decoder, self.sinks, self.opts, stop=self._stop.is_set, tick=0.25)
        except BaseException as exc:  # noqa: BLE001 - re-raised in the test's thread
            self.error = exc

    def stop(self) -> float:
        t = time.monotonic()
        self._stop.set()
        self._thread.join(timeout=30)
        assert not self._thread.is_alive()
        if self.error is not None:
            raise self.error
        return t


def _node(channel: str):
    od = canopen.ObjectDictionary()
    od.add_object(variable(0x1017, 0, "Producer heartbeat time", UNSIGNED16, "rw", PERIOD_MS))
    net = canopen.Network()
    net.connect(interface="virtual", channel=channel)
    local = canopen.LocalNode(NODE, od)
    net.add_node(local)
    local.nmt.state = "OPERATIONAL"  # a heartbeat of state 0 would be a boot-up
    return net, local


def _heartbeat(got):
    return [(at, f) for at, f in got if f.rule == "heartbeat" and f.node == NODE]


@pytest.mark.slow
def test_only_node_silent_reported_on_the_wall_clock(tmp_path):
    channel = unique_channel("wallclock")
    session = _Session(channel, _rules(tmp_path))
    net, local = _node(channel)
    try:
        time.sleep(0.3)  # the session's bus is open
        local.nmt.start_heartbeat(PERIOD_MS)
        time.sleep(1.0)
        local.nmt.stop_heartbeat()
        t_silent = time.monotonic()  # no frame at all from here on
        time.sleep(BOUND_S + 1.5)
    finally:
        local.nmt.stop_heartbeat()
        t_stop = session.stop()
        net.disconnect()
    hb = _heartbeat(session.sink.got)
    live = [(at, f) for at, f in hb if not f.at_end]
    assert len(hb) == len(live) == 1, [f.message for _, f in hb]  # once, and not at exit
    at, f = live[0]
    assert at < t_stop
    assert at - t_silent <= BOUND_S, (at - t_silent, f.message)
    assert f.severity == "error" and f.expected == PERIOD_MS
    assert f.message.startswith("heartbeat stopped: none since +")
    assert "; no frame from any node since +" in f.message
    assert "(the adapter or the logger may have stopped)" in f.message
    # the finding's bus time: past the last heartbeat by the deadline, not by the stop
    assert f.t - (f.t - f.t_rel) > 0 and PERIOD_MS / 1000 < at - t_silent + PERIOD_MS / 1000
    # at exit the node had not come back: completed with the silence until the session ended
    assert " ms until the session ended); no frame from any node since +" in f.message
    assert abs(f.measured / 1000 - (t_stop - t_silent)) < 0.5 + PERIOD_MS / 1000
    others = [f.rule for _, f in session.sink.got if f.rule != "heartbeat"]
    assert others == []


class _Screen(DashboardSink):
    """The live dashboard rendered headless (Rich's recording console) as the terminal
    would be redrawn: the first wall time its findings panel showed `wanted`."""

    def __init__(self, wanted: str) -> None:
        super().__init__(checking=True, show=False, every=0.05)
        self.wanted = wanted
        self.seen: tuple[float, str] | None = None
        self._drawn = 0.0

    def tick(self, now: float) -> None:
        if self.seen is not None or now - self._drawn < self.every:
            return
        self._drawn = now
        console = Console(record=True, width=160, color_system=None, file=io.StringIO())
        console.print(self.view.render(height=50))
        text = console.export_text()
        panel = text.split("Findings (latest)", 1)[-1].split("Events", 1)[0]
        line = next((x for x in panel.splitlines() if self.wanted in x), None)
        if line is not None:
            self.seen = (now, line)


@pytest.mark.slow
def test_dashboard_findings_panel_shows_the_silent_node(tmp_path):
    channel = unique_channel("wallclock-dash")
    screen = _Screen(f"heartbeat: node {NODE} heartbeat stopped")
    session = _Session(channel, _rules(tmp_path), sinks=[screen])
    net, local = _node(channel)
    try:
        time.sleep(0.3)
        local.nmt.start_heartbeat(PERIOD_MS)
        time.sleep(0.8)
        local.nmt.stop_heartbeat()
        t_silent = time.monotonic()
        time.sleep(BOUND_S + 1.0)
    finally:
        local.nmt.stop_heartbeat()
        t_stop = session.stop()
        net.disconnect()
    assert screen.seen is not None, list(screen.view.findings)
    at, line = screen.seen
    assert at - t_silent <= BOUND_S and at < t_stop, (at - t_silent, line)
    assert "no frame from any node since" in line
    assert screen.view.violations == 1


@pytest.mark.slow
def test_every_producer_stopping_each_reported(tmp_path):
    """A heartbeat and python-canopen's SYNC producer stop together: the bus goes quiet.
    Each deadline is reported on the wall clock, once, each saying no frame came at all."""
    channel = unique_channel("wallclock-all")
    session = _Session(channel, _rules(tmp_path, "  sync: {period_us: 100000}\n"))
    net, local = _node(channel)
    try:
        time.sleep(0.3)
        local.nmt.start_heartbeat(PERIOD_MS)
        net.sync.start(PERIOD_MS / 1000)
        time.sleep(1.0)
        net.sync.stop()
        local.nmt.stop_heartbeat()
        t_silent = time.monotonic()
        time.sleep(BOUND_S + 1.0)
    finally:
        net.sync.stop()
        local.nmt.stop_heartbeat()
        t_stop = session.stop()
        net.disconnect()
    got = {}
    for at, f in session.sink.got:
        got.setdefault(f.rule, []).append((at, f))
    assert sorted(got) == ["heartbeat", "sync"], {
        r: [f.message for _, f in v] for r, v in got.items()
    }
    for rule, hits in got.items():
        assert len(hits) == 1, [f.message for _, f in hits]
        at, f = hits[0]
        assert at - t_silent <= BOUND_S and at < t_stop, (rule, at - t_silent)
        assert "; no frame from any node since +" in f.message
    assert got["sync"][0][1].message.startswith("no SYNC since +")


@pytest.mark.slow
def test_node_back_late_is_one_finding(tmp_path):
    """The silence seen on the wall clock, then the node's next heartbeat: one finding,
    completed with the whole gap (a dropout), not a second one."""
    channel = unique_channel("wallclock-back")
    session = _Session(channel, _rules(tmp_path))
    net, local = _node(channel)
    try:
        time.sleep(0.3)
        local.nmt.start_heartbeat(PERIOD_MS)
        time.sleep(0.8)
        local.nmt.stop_heartbeat()
        t_silent = time.monotonic()
        time.sleep(BOUND_S + 0.8)
        local.nmt.start_heartbeat(PERIOD_MS)
        time.sleep(0.8)
    finally:
        local.nmt.stop_heartbeat()
        session.stop()
        net.disconnect()
    hb = _heartbeat(session.sink.got)
    assert len(hb) == 1, [f.message for _, f in hb]
    at, f = hb[0]
    assert at - t_silent <= BOUND_S
    # completed when the node came back: the whole gap, as `check` of the recording says
    assert f.message.startswith("heartbeat dropout: no heartbeat for ")
    assert f.measured > (BOUND_S + 0.8) * 1000 - 200


@pytest.mark.slow
def test_unanswered_sdo_request_times_out_on_the_tick(tmp_path):
    """python-canopen's SDO client asks node 9, which is not there: the only frame on the
    bus. The tracker's timeout (1 s) is reported while the client still waits."""
    channel = unique_channel("wallclock-sdo")
    session = _Session(channel, _rules(tmp_path), sdo_timeout=1.0)
    net = canopen.Network()
    net.connect(interface="virtual", channel=channel)
    remote = canopen.RemoteNode(9, canopen.ObjectDictionary())
    net.add_node(remote)
    remote.sdo.RESPONSE_TIMEOUT = 4.0  # the client gives up (an abort frame) after the check
    asked: list[float] = []

    def ask() -> None:
        asked.append(time.monotonic())
        try:
            remote.sdo.upload(0x1008, 0)
        except SdoError:
            pass

    try:
        time.sleep(0.3)
        client = threading.Thread(target=ask, daemon=True)
        client.start()
        time.sleep(1.0 + 0.5 + 0.8)
        t_stop = session.stop()  # before the client's own 4 s timeout
        client.join(timeout=10)
    finally:
        net.disconnect()
    sdo = [(at, f) for at, f in session.sink.got if f.rule == "sdo"]
    assert len(sdo) == 1, [f.message for _, f in sdo]
    at, f = sdo[0]
    assert not f.at_end and at < t_stop
    assert at - asked[0] <= 1.0 + 0.5
    assert f.node == 9 and f.measured == "timeout"
    assert f.message.startswith("SDO upload 0x1008:00 timeout: no frame within 1 s")


def test_log_file_end_is_no_silence(tmp_path):
    """The same traffic as a file (no live source, no tick): the log ends after the last
    heartbeat, which says nothing about the node."""
    rows = [(round(k * PERIOD_MS / 1000, 3), 0x700 + NODE, b"\x05") for k in range(20)]
    opts = Options(rules=_rules(tmp_path), checks=True)
    decoder = build_decoder(opts, build_checker(opts))
    sink = _Findings()
    run(MemorySource(from_rows(rows)), decoder, [sink], opts)
    assert sink.got == []
