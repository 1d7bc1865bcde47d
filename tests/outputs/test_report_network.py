"""The report's network page: who produces and who consumes which PDO, as the
configuration in force at the end of the log says, with the consistency rule's
contradictions in red. Checked against the frames as python-can reads them and against
the simulator's injected COB-ID collision (the page parsed with html.parser)."""

from __future__ import annotations

import re
from html.parser import HTMLParser
from pathlib import Path

import can
from conftest import SAMPLES

from tests.outputs.test_report import cli, parse, table_with

NETWORK = SAMPLES / "network.toml"


class _Svg(HTMLParser):
    """The network section's circles (label -> class) and arrows' classes."""

    def __init__(self) -> None:
        super().__init__()
        self.inside = False
        self.circles: list[str] = []
        self.labels: list[str] = []
        self.lines: list[str] = []
        self._text = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self.inside = a.get("id") == "network"
        elif self.inside and tag == "circle":
            self.circles.append(a.get("class") or "")
        elif self.inside and tag == "line":
            self.lines.append(a.get("class") or "")
        self._text = self.inside and tag == "text"

    def handle_data(self, data):
        if self._text and len(self.labels) < len(self.circles):
            self.labels.append(data)
        self._text = False


def _page(tmp: Path, log: Path) -> tuple[list[list[str]], _Svg]:
    out = tmp / "report.html"
    r = cli("report", str(log), "--network", str(NETWORK), "-o", str(out), "-q")
    assert r.returncode in (0, 1), r.stderr
    text, tables, _ = parse(out)
    svg = _Svg()
    svg.feed(text)
    return table_with(tables, "relation", "COB-ID")[1:], svg


def test_every_tpdo_on_the_wire_has_its_producer(tmp_path):
    rows, svg = _page(tmp_path, SAMPLES / "commissioning.log")
    produced = {r[3]: r[1] for r in rows if r[0] == "PDO"}
    # TPDO1-4 of a node (0x180/0x280/0x380/0x480 + node-ID), as python-can reads the log
    seen = {
        m.arbitration_id
        for m in can.LogReader(str(SAMPLES / "commissioning.log"))
        if not m.is_error_frame and (m.arbitration_id & 0x780) in (0x180, 0x280, 0x380, 0x480)
    }
    assert seen
    for cob in seen:
        assert str(cob & 0x7F) in produced[f"0x{cob:03X}"].split(", "), hex(cob)
    assert not any(r[4] for r in rows)  # a healthy network: no contradiction
    assert "red" not in " ".join(svg.circles + svg.lines)
    # each configured node drawn, and the master (not configured) as "other"
    assert {"3", "5", "6", "7", "other"} <= set(svg.labels)
    assert svg.lines  # the master's RPDOs to the nodes, the nodes' TPDOs to it


def test_a_cob_id_collision_is_red(tmp_path):
    log = tmp_path / "cf.log"
    r = cli("simulate", "--scenario", "commissioning-faults", "--to", str(log), "--duration", "10")
    assert r.returncode == 0, r.stderr
    rows, svg = _page(tmp_path, log)
    collision = [r for r in rows if r[3] == "0x283"]
    assert collision == [["PDO", "3, 10", "-", "0x283", "contradiction (consistency)"]]
    red = [lab for lab, c in zip(svg.labels, svg.circles, strict=True) if c == "red"]
    assert red == ["10"]  # the node whose TPDO2 moved onto node 3's COB-ID
    assert sum("red" in c for c in svg.lines) >= 2  # both producers' arrows
    others = [r for r in rows if r[3] != "0x283"]
    assert others and not any(r[4] for r in others)
    assert all(re.fullmatch(r"0x[0-9A-F]{3}|-", r[3]) for r in rows)
