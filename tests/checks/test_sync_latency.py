"""Synchronous PDOs' latency after SYNC: per COB-ID, beside the window 0x1007 in force.

The traffic: SYNC every 10 ms; node 5's TPDO1 set to type 1 by an SDO write, sent
0.30-0.79 ms after each SYNC (one at 0.9 ms); the master's RPDO1 to node 5 (type 1)
0.1 ms after; 0x1007 written as 800 us. The figures are numpy's of the latencies put
in; `check --timing`, `decode --summary`, load() and the report agree; the PDO outside
the window stays the pdo_sync rule's one finding.
"""

from __future__ import annotations

import json
import subprocess
import sys
from html.parser import HTMLParser

import numpy as np
import pytest

import cananalyze

SYNCS = 200


def _log(path, timed: bool = True) -> list[float]:
    lines = []

    def put(t: float, cob: int, data: str) -> None:
        if timed:
            lines.append(f"({t:.6f}) vcan0 {cob:03X}#{data}")
        else:  # candump's screen format, as printed without -t: no times
            d = bytes.fromhex(data)
            lines.append(f"  can0  {cob:03X}   [{len(d)}]  {' '.join(f'{b:02X}' for b in d)}")

    put(0.0, 0x705, "00")
    put(0.010, 0x605, "2F00180201000000")  # 0x1800:02 = 1: TPDO1 every SYNC
    put(0.0105, 0x585, "6000180200000000")
    put(0.020, 0x605, "2F00140201000000")  # 0x1400:02 = 1: RPDO1 applied at each SYNC
    put(0.0205, 0x585, "6000140200000000")
    put(0.030, 0x605, "2307100020030000")  # 0x1007 = 800 us
    put(0.0305, 0x585, "6007100000000000")
    put(0.040, 0x000, "0100")
    late = []
    for k in range(SYNCS):
        ts = 0.1 + k * 0.010
        put(ts, 0x080, "")
        ms = 0.9 if k == 150 else 0.3 + 0.01 * (k % 50)
        late.append(ms)
        put(ts + 0.0001, 0x205, "0102")
        put(ts + ms / 1000, 0x185, "0A0B")
    path.write_text("\n".join(lines) + "\n")
    return late


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("sync") / "sync.log"
    return path, np.array(_log(path))


def test_load_gives_numpys_figures(log):
    path, late = log
    df = cananalyze.load(path).sync_latency.set_index("cob_id")
    tpdo = df.loc[0x185]
    assert (tpdo["node"], tpdo["pdo"], tpdo["type"], tpdo["count"]) == (5, "tpdo1", 1, SYNCS)
    for name, want in (("min", late.min()), ("median", np.median(late)), ("max", late.max())):
        assert tpdo[name] == pytest.approx(want, abs=1e-3), name
    assert tpdo["mean"] == pytest.approx(late.mean(), abs=1e-3)
    assert tpdo["jitter"] == pytest.approx(late.std(), abs=1e-3)
    assert tpdo["window_ms"] == 0.8
    assert tpdo["margin_ms"] == pytest.approx(0.8 - late.max(), abs=1e-3)
    rpdo = df.loc[0x205]
    assert (rpdo["pdo"], rpdo["count"]) == ("rpdo1", SYNCS)
    assert rpdo["max"] == pytest.approx(0.1, abs=1e-3)
    assert rpdo["margin_ms"] == pytest.approx(0.7, abs=1e-3)


def _cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *map(str, args)], capture_output=True, text=True
    )


def test_check_timing_lines_and_the_one_finding(log):
    path, late = log
    run = _cli("check", path, "--timing", "-q")
    assert run.returncode == 1  # the PDO 0.9 ms after SYNC, window 0.8 ms
    findings = [x for x in run.stdout.splitlines() if "[error]" in x]
    assert len(findings) == 1 and "pdo_sync: sent 0.9 ms after SYNC" in findings[0]
    line = next(x for x in run.stdout.splitlines() if x.startswith("  0x185 (node 5 TPDO1"))
    assert line == (
        f"  0x185 (node 5 TPDO1 type 1): n={SYNCS} min {late.min():.2f} "
        f"median {np.median(late):.2f} mean {late.mean():.2f} p99 "
        f"{np.quantile(late, 0.99, method='inverted_cdf'):.2f} max {late.max():.2f} "
        f"jitter {late.std():.2f} ms; window 0x1007 0.8 ms, margin {0.8 - late.max():.2f} ms"
    )


def test_summary_json_has_them(log):
    path, _ = log
    run = _cli("decode", path, "--summary", "--format", "jsonl")
    assert run.returncode == 0, run.stderr
    rec = json.loads(run.stdout.splitlines()[-1])
    got = rec["timing"]["sync_latency"]
    assert set(got) == {str(0x185), str(0x205)}
    assert got[str(0x185)]["count"] == SYNCS and got[str(0x185)]["window_ms"] == 0.8


class _Cells(HTMLParser):
    """The text of every table cell under the section with id "sync"."""

    def __init__(self) -> None:
        super().__init__()
        self.inside, self.cell, self.rows, self.plots = False, None, [], 0

    def handle_starttag(self, tag, attrs):
        if tag == "section":
            self.inside = dict(attrs).get("id") == "sync"
        if self.inside and tag == "tr":
            self.rows.append([])
        if self.inside and tag == "td":
            self.cell = ""
        if self.inside and tag == "div" and dict(attrs).get("class") == "plot":
            self.plots += 1

    def handle_endtag(self, tag):
        if tag == "td" and self.cell is not None:
            self.rows[-1].append(self.cell)
            self.cell = None

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data


def test_report_has_a_row_and_a_plot_per_cob_id(log, tmp_path):
    path, late = log
    html = tmp_path / "r.html"
    run = _cli("report", path, "-o", html, "-q")
    assert run.returncode == 1, run.stderr
    cells = _Cells()
    cells.feed(html.read_text())
    rows = [r for r in cells.rows if r]
    assert [r[:5] for r in rows] == [
        ["0x185", "5", "TPDO1", "1", str(SYNCS)],
        ["0x205", "5", "RPDO1", "1", str(SYNCS)],
    ]
    assert rows[0][8] == f"{late.max():.3f}" and rows[0][10] == "0.8"
    assert cells.plots == 2  # a histogram per COB-ID


def test_a_log_without_times_has_no_latency(tmp_path):
    path = tmp_path / "screen.txt"
    _log(path, timed=False)
    assert cananalyze.load(path).sync_latency.empty
