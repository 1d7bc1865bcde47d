"""Issue 44 items 2 and 3: the report's plots say what the log knows. A signal that stops
coming is a gap, not a slope or a held step; a period holds over the interval it
measures (a dropout is a plateau); a log without times is drawn against its lines, with
no bus load, periods nor latencies (every frame has one time). Figures read back with
the page's documented layout (`test_report.page_figures`), the tables parsed."""

from __future__ import annotations

import numpy as np
from conftest import SAMPLES, real_file
from test_report import cli, parse, table_with

T0 = 1767225600.0


def _paused_log(path) -> None:
    """Node 3's TPDO1 (0x183) at 10 Hz for 5 s, nothing for 3 s, then 5 s more."""
    lines = []
    for i in range(130):
        if 50 <= i < 80:
            continue
        lines.append(f"({T0 + i * 0.1:.6f}) can0 183#{(i * 7) % 256:02X}{i % 2:02X}00000000")
    path.write_text("\n".join(lines) + "\n")


def test_a_signal_that_stops_is_a_gap(tmp_path):
    log, page = tmp_path / "paused.log", tmp_path / "paused.html"
    _paused_log(log)
    r = cli("report", str(log), "--network", str(SAMPLES / "network.toml"), "-o", str(page))
    assert page.exists(), r.stderr
    _, _, figs = parse(page)
    signals = [f for f in figs.values() if "TPDO1 (0x183)" in f["layout"]["title"]["text"]]
    assert len(signals) == 1 and signals[0]["data"]
    for trace in signals[0]["data"]:
        x, y = np.asarray(trace["x"], float), np.asarray(trace["y"], float)
        gap = np.flatnonzero(np.isnan(y))
        assert gap.size == 1, trace["name"]  # one pause, one break
        k = int(gap[0])
        assert x[k - 1] < 5.0 and x[k + 1] > 7.9  # between the last frame and the next
        assert np.isfinite(np.delete(y, k)).all()
    load = next(f for f in figs.values() if f["layout"]["title"]["text"].startswith("Bus load"))
    assert np.isnan(np.asarray(load["data"][0]["y"], float)).sum() == 1


def test_a_steady_signal_has_no_gap_and_periods_are_held(tmp_path):
    """demo.log, every PDO steady at 10 Hz: no break in any signal; each heartbeat period
    is drawn over the interval it measures (plotly's 'vh')."""
    page = tmp_path / "demo.html"
    r = cli(
        "report",
        str(SAMPLES / "demo.log"),
        "--network",
        str(SAMPLES / "network.toml"),
        "-o",
        str(page),
    )
    assert page.exists(), r.stderr
    _, _, figs = parse(page)
    periods = signals = 0
    for f in figs.values():
        title = f["layout"]["title"]["text"]
        for trace in f["data"]:
            if title.endswith("heartbeat period") and trace["name"] == "measured":
                assert trace["line"]["shape"] == "vh"
                periods += 1
            elif "PDO" in title and trace.get("type") == "scatter":
                assert np.isfinite(np.asarray(trace["y"], float)).all(), (title, trace["name"])
                signals += 1
    assert periods >= 2 and signals >= 4


def test_a_log_without_times_is_drawn_by_line(tmp_path):
    log = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    page = tmp_path / "log2.html"
    r = cli("report", str(log), "-o", str(page))
    assert page.exists(), r.stderr
    text, tables, figs = parse(page)
    titles = [f["layout"]["title"]["text"] for f in figs.values()]
    assert not any(t.startswith("Bus load") or " period" in t for t in titles)
    assert {f["layout"]["xaxis"]["title"]["text"] for f in figs.values()} == {"line"}
    lanes = next(f for f in figs.values() if f["layout"]["title"]["text"] == "NMT state per node")
    starts = sorted(float(b) for tr in lanes["data"] for b in np.asarray(tr["base"]))
    assert starts == [3, 18, 29, 60, 1239]  # the lines of the boot-up and the NMT commands
    rows = table_with(tables, "channel", "mean load")
    assert rows[1][3:] == ["-", "-"]
    sdo = table_with(tables, "node", "median ms")
    assert sdo[1][3:] == ["-", "-", "-", "-"]
    assert "(the log has no timestamps)" in text
    assert "0.00 kbit/s" not in text
