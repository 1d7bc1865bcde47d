"""The live dashboard, rendered to text: nodes, states, heartbeat periods, EMCYs,
PDO values with units (from the real PDO decoder) and the event log, from the demo
session's real frames, and findings when a Checker runs."""

from __future__ import annotations

import numpy as np
from conftest import SAMPLES
from rich.console import Console

from cananalyze.checks.build import build_checker
from cananalyze.formats.source import read_all
from cananalyze.outputs.dashboard import LiveView
from cananalyze.pipeline import Decoder, Options, build_decoder


def _cells(text: str) -> list[list[str]]:
    """Table body rows as lists of cell texts."""
    out = []
    for line in text.splitlines():
        if line.startswith("│") and line.count("│") > 3:
            out.append([c.strip() for c in line.strip("│").split("│")])
    return out


def _render(view: LiveView, wall: float) -> str:
    console = Console(record=True, width=140, color_system=None)
    console.print(view.render(wall=wall, height=60))
    return console.export_text()


def test_dashboard_shows_nodes_signals_and_events():
    frames = read_all(SAMPLES / "demo.log")
    # the pipeline as `live --device 3=mcb560` builds it; node 5 is left to SDO identification
    dec = build_decoder(Options(devices={3: "mcb560"}))
    view = LiveView(bitrate=500_000, devices={10: "guarded node"}, model=dec.network)
    t0 = float(frames.t[0])
    # feed the session in 50 ms slices, as the live source would, up to 1.25 s (EMCY active)
    cut = t0 + 1.25
    edges = np.arange(t0, cut + 0.05, 0.05)
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (frames.t >= a) & (frames.t < b)
        view.add(dec.decode(frames.take(sel)), wall=b)
    text = _render(view, wall=cut)
    cells = _cells(text)
    row = {int(c[0]): " | ".join(c) for c in cells if len(c) == 7}
    assert set(row) == {3, 5, 10}
    # identified from the SDO-read 0x1018/0x1000/0x1008 against the built-in profiles
    assert "Datexel DAT 7014" in row[5] and "operational" in row[5]
    assert "ANDIG MCB-560" in row[3]  # from --device
    assert "guarded node" in row[10]
    assert "SDO write 0x1017:00" in row[5]  # the last SDO transaction
    assert "100 ms" in row[5] and "100 ms" in row[3]  # measured heartbeat period
    assert "0x8100" in row[3]  # MCB-560 EMCY raised at 1.06 s, still active
    assert "0x8100" not in row[5]
    assert "SDO" in row[5]  # last SDO seen for node 5
    # guarded node 10: state from the guard reply, no heartbeat period
    assert "operational" in row[10]
    # TPDO2 of the DAT 7014 at 1.2 s: k=11 -> 226, 209, 7, 1000 (x0.1 degC)
    # one row per PDO with its signals side by side, units from the profiles
    sig = {(c[0], c[1]): c[2] for c in cells if len(c) == 4 and c[1].startswith("tpdo")}
    assert set(sig) == {("3", "tpdo1"), ("3", "tpdo2"), ("5", "tpdo2")}
    # TPDO2 of the DAT 7014 at 1.2 s: k=11 -> 226, 209, 7, 1000 (x0.1 degC)
    assert sig["5", "tpdo2"] == "ch1 22.6 °C   ch2 20.9 °C   ch3 0.7 °C   ch4 100 °C"
    # MCB-560 TPDO2: analog inputs in mV through its built-in profile
    assert sig["3", "tpdo2"].startswith("analog0 ") and sig["3", "tpdo2"].count(" mV") == 4
    assert "NMT start all nodes" in text
    assert "node 3 EMCY 0x8100" in text
    assert "bus load" in text and "frames" in text

    # the rest of the session: the EMCY is reset and disappears from the node row
    rest = frames.take(frames.t >= cut)
    view.add(dec.decode(rest), wall=cut + 1.0)
    text = _render(view, wall=cut + 1.0)
    row3 = " | ".join(next(c for c in _cells(text) if len(c) == 7 and c[0] == "3"))
    assert "0x8100" not in row3
    assert "EMCY error reset" in text


def _widths(text: str) -> list[list[int]]:
    """Column separator positions of every table line."""
    return [[i for i, ch in enumerate(x) if ch in "│┃"] for x in text.splitlines() if "│" in x]


def test_findings_and_steady_columns(tmp_path):
    """A Checker on the live decoder: findings land in the event log with their level and
    in the header count; column positions do not move as values change between refreshes."""
    frames = read_all(SAMPLES / "faults.log")
    checker = build_checker(SAMPLES / "rules.yaml")
    dec = build_decoder(Options(network=SAMPLES / "network.toml"), checker)
    view = LiveView(bitrate=500_000, model=dec.network, checking=True)
    t0 = float(frames.t[0])
    seps = set()
    texts = []
    for k, a in enumerate(np.arange(t0, t0 + 10.0, 0.5)):
        view.add(dec.decode(frames.take((frames.t >= a) & (frames.t < a + 0.5))), wall=100 + k)
        text = _render(view, wall=100 + k + 0.5)
        texts.append(text)
        seps.update(tuple(w) for w in _widths(text))
    view.add(dec.finish(), wall=200)
    text = _render(view, wall=200)
    assert len({s for s in seps if len(s) == 8}) == 1  # nodes table (7 columns)
    assert len({s for s in seps if len(s) == 5}) == 1  # signals table (4 columns)
    failing = [f for f in checker.findings if f.fails]
    assert view.violations == len(failing) > 10
    assert f"check: {len(failing)} violation(s)" in text
    assert "assert_signal: node 5 ch3 = 3276.7 outside -200..850" in text
    levels = {lvl for _, lvl, txt in view.events if txt.startswith("assert_signal")}
    assert levels == {"error"}
    # the devices the network file declares
    rows = {c[0]: c for c in _cells(text) if len(c) == 7}
    assert rows["7"][1].startswith("ICP DAS I-7231D") and rows["6"][1].startswith(
        "Datexel DAT 7130"
    )


def test_rate_and_load_follow_the_wall_clock():
    frames = read_all(SAMPLES / "demo.log")
    view = LiveView(bitrate=125_000)
    dec = Decoder()
    view.add(dec.decode(frames.take(slice(0, 0))), wall=100.0)
    view.add(dec.decode(frames.take(slice(0, 100))), wall=100.5)
    assert view.frame_rate() == 200.0
    assert view.bus_load() is not None and 0 < view.bus_load() < 100
    # a quiet second later the window holds no frames
    view.add(dec.decode(frames.take(slice(0, 0))), wall=102.0)
    view.add(dec.decode(frames.take(slice(0, 0))), wall=102.5)
    assert view.frame_rate() == 0.0


def test_names_are_text_not_rich_markup():
    """A device's name (network file, EDS) in rich markup: shown as written, not styled nor
    made a terminal hyperlink (OSC 8), on a colour terminal (issue 38 item 1)."""
    frames = read_all(SAMPLES / "demo.log")
    dec = build_decoder(Options())
    name = "[link=http://example.invalid]x[/link][bold red]n"
    view = LiveView(bitrate=500_000, devices={10: name}, model=dec.network)
    view.add(dec.decode(frames), wall=float(frames.t[-1]))
    console = Console(record=True, width=200, force_terminal=True, color_system="truecolor")
    console.print(view.render(wall=float(frames.t[-1]), height=60))
    styled = console.export_text(styles=True, clear=False)
    assert "\x1b]8;" not in styled  # no hyperlink escape
    assert "[link=http://example.invalid]x[/link]" in console.export_text()  # as written
