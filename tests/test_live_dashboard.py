"""The live dashboard, rendered to text: nodes, states, heartbeat periods, EMCYs,
PDO values with units and the event log, from the demo session's real frames."""

from __future__ import annotations

import argparse

import numpy as np
from conftest import SAMPLES
from rich.console import Console

from cananalyze.cli.pipeline import build_decoder
from cananalyze.decoded import SignalBlock
from cananalyze.decoder import Decoder
from cananalyze.io.source import read_all
from cananalyze.network.profile import load_builtin
from cananalyze.outputs.dashboard import LiveView
from cananalyze.protocol.pdo_decode import decode_pdo


class Dat7014Pdo:
    """Stands in for the PDO processor: the DAT 7014 profile's TPDO2 decoded with decode_pdo."""

    def __init__(self) -> None:
        self.cfg = next(p for p in load_builtin("dat7014").pdos(5) if p.number == 2)

    def process(self, batch) -> None:
        rows = np.flatnonzero(batch.frames.can_id == self.cfg.cob_id)
        if rows.size:
            cols = decode_pdo(batch.frames.data[rows], batch.frames.dlc[rows], self.cfg.mapping)
            units = {e.name: e.unit for e in self.cfg.mapping}
            batch.signals.append(SignalBlock(rows, 5, "tpdo2", self.cfg.cob_id, cols.values, units))

    def finish(self, batch) -> None:
        pass


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
    # the SDO tracker as `decode` wires it, then the PDO decoding
    dec = Decoder(build_decoder(argparse.Namespace(sdo_timeout=1.0)).processors + [Dat7014Pdo()])
    view = LiveView(bitrate=500_000, devices={10: "guarded node"})
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
    assert "guarded node" in row[10]
    assert "SDO write 0x1017:00" in row[5]  # the last SDO transaction
    assert "100 ms" in row[5] and "100 ms" in row[3]  # measured heartbeat period
    assert "0x8100" in row[3]  # MCB-560 EMCY raised at 1.06 s, still active
    assert "0x8100" not in row[5]
    assert "SDO" in row[5]  # last SDO seen for node 5
    # guarded node 10: state from the guard reply, no heartbeat period
    assert "operational" in row[10]
    # TPDO2 of the DAT 7014 at 1.2 s: k=11 -> 226, 209, 7, 1000 (x0.1 degC)
    sig = {c[2]: " | ".join(c) for c in cells if len(c) == 6 and c[1] == "tpdo2"}
    assert set(sig) == {"ch1", "ch2", "ch3", "ch4"}
    assert "22.6" in sig["ch1"] and "°C" in sig["ch1"]
    assert "100" in sig["ch4"]
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
