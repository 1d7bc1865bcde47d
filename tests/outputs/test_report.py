"""`cananalyze report` and `check --html`: the page's content, read back independently
(the HTML parsed, plotly's figure JSON loaded, frames counted by python-can), its
accumulators against numpy on every value, and the page in a real browser."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import can
import numpy as np
import pytest
from conftest import SAMPLES, generated_log, real_file

from cananalyze.outputs.report.accum import Envelope, WindowSums

PACKED = re.compile(r'<script type="text/plain" id="(\w+)">(.*?)</script>', re.S)


def unpack7(text: str) -> bytes:
    """The page's 7-bit text back to bytes, as the docstring of `report/encode.py` says
    (each character's low 7 bits, most significant first; U+0100 + v stands for v)."""
    codes = np.frombuffer(text.encode("utf-16-le"), "<u2")
    assert ((codes < 0x80) | np.isin(codes, [0x100, 0x10D, 0x13C])).all()
    assert not np.isin(codes, [0, 13, 60]).any()  # NUL, CR, '<': what script text changes
    bits = ((codes[:, None] & 0x7F) >> np.arange(6, -1, -1)) & 1
    return np.packbits(bits.astype(np.uint8).ravel()[: len(text) * 7 // 8 * 8]).tobytes()


def page_figures(text: str) -> dict:
    """The page's figures, read as its documented layout says (`encode.Blob`): gzip of
    a uint32 JSON length, the JSON, then 8-byte aligned integer arrays, each
    {"q": [offset, count, bytes, form, first, exponent]} in the JSON; as numpy arrays."""
    import gzip
    import struct

    raw = gzip.decompress(unpack7(dict(PACKED.findall(text))["figures"]))
    (n,) = struct.unpack_from("<I", raw)
    base = -(-(4 + n) // 8) * 8

    def revive(d: dict):
        if list(d) != ["q"]:
            return d
        at, count, size, form, first, e = d["q"]
        a = np.frombuffer(raw, {2: "<i2", 4: "<i4", 8: "<f8"}[size], count, base + at)
        if form == 2:
            return a
        k = first + (np.cumsum(a, dtype=np.int64) if form == 1 else a.astype(np.int64))
        return k / 10.0**-e if e < 0 else k * 10.0**e

    return dict(json.loads(raw[4 : 4 + n], object_hook=revive))


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, timeout=300
    )


class Tables(HTMLParser):
    """Every <table> as rows of cell texts, and the text of each element with an id."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: list[list[list[str]]] = []
        self._row: list[str] | None = None
        self._cell: list[str] | None = None
        self.summaries: list[str] = []
        self._summary: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "summary":
            self._summary = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[-1].append(self._row)
            self._row = None
        elif tag == "summary":
            self.summaries.append("".join(self._summary))
            self._summary = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        if self._summary is not None:
            self._summary.append(data)


def parse(path: Path) -> tuple[str, Tables, dict]:
    text = path.read_text()
    t = Tables()
    t.feed(text)
    return text, t, page_figures(text)


def table_with(tables: Tables, first_header: str, header: str) -> list[list[str]]:
    for tb in tables.tables:
        if tb and tb[0][0] == first_header and header in tb[0]:
            return tb
    raise AssertionError(f"no table with {header}")


@pytest.fixture(scope="module")
def faults_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "faults.html"
    r = cli(
        "report",
        str(SAMPLES / "faults.log"),
        "--network",
        str(SAMPLES / "network.toml"),
        "--rules",
        str(SAMPLES / "rules.yaml"),
        "-o",
        str(out),
        "-q",
    )
    assert r.returncode == 1, r.stderr  # violations, as `check`
    return out


def test_report_holds_the_checks_findings_grouped(faults_report, tmp_path):
    found = tmp_path / "f.json"
    r = cli(
        "check",
        str(SAMPLES / "faults.log"),
        "--network",
        str(SAMPLES / "network.toml"),
        "--rules",
        str(SAMPLES / "rules.yaml"),
        "--json",
        str(found),
        "-q",
    )
    assert r.returncode == 1
    findings = json.loads(found.read_text())
    text, tables, _ = parse(faults_report)
    assert 'class="verdict fail"' in text
    assert f"{len(findings)} violation(s)" in text
    groups = {(f["node"], f["rule"]) for f in findings}
    assert len(tables.summaries) == len(groups)
    for node, rule in groups:
        who = "bus" if node is None else f"node {node}"
        n = sum(1 for f in findings if (f["node"], f["rule"]) == (node, rule))
        assert any(s.startswith(f"{who} · {rule} · {n} finding(s)") for s in tables.summaries)


def test_report_counts_every_frame_per_channel(faults_report):
    _, tables, _ = parse(faults_report)
    with can.LogReader(str(SAMPLES / "faults.log")) as reader:
        msgs = list(reader)
    buses = table_with(tables, "channel", "frames")
    assert buses[1][0] == "can0"
    assert int(buses[1][1].replace(",", "")) == len(msgs)
    # error frames: SocketCAN's CAN_ERR_FLAG (0x20000000) in the candump identifier
    ids = [ln.split()[2].split("#")[0] for ln in (SAMPLES / "faults.log").read_text().splitlines()]
    errors = sum(1 for i in ids if len(i) == 8 and int(i, 16) & 0x20000000)
    assert errors == 3 and int(buses[1][2]) == errors


def test_report_sdo_aborts_and_emcys_from_the_log(faults_report):
    _, tables, _ = parse(faults_report)
    aborts = table_with(tables, "time", "code")
    codes = {row[5] for row in aborts[1:]}
    assert {"0x06010002", "0x06020000", "0x05040000"} <= codes
    emcy = table_with(tables, "time", "active for")
    with can.LogReader(str(SAMPLES / "faults.log")) as reader:
        raised = [
            m for m in reader if 0x81 <= m.arbitration_id <= 0xFF and bytes(m.data[:2]) != b"\0\0"
        ]
    assert len(emcy) - 1 == len(raised)
    # node 3's 0x8100 at +1.391 s is reset at +2.891 s (samples/README.md); node 7's never
    by_code = {row[2]: row[5] for row in emcy[1:]}
    assert by_code["0x8100"] == "1.500 s"
    assert by_code["0xFF00"] == "still active at the end of the log"


def test_report_plots_signals_with_units_and_heartbeats_against_config(faults_report):
    _, _, figs = parse(faults_report)
    titles = {f["layout"]["title"]["text"]: f for f in figs.values()}
    tpdo = titles["Node 5 TPDO2 (0x285)"]
    assert tpdo["layout"]["yaxis"]["title"]["text"] == "°C"
    assert [d["name"] for d in tpdo["data"]] == ["ch1 (°C)", "ch3 (°C)"]
    hb = titles["Node 6 heartbeat period"]
    measured, configured = hb["data"]
    assert configured["name"] == "configured"
    assert set(configured["y"]) == {100}
    # the dropout (samples/README.md: 1.6 s without heartbeat) is in the envelope's max
    y = _values(measured["y"])
    assert 1550 < max(y) < 1650
    assert "Bus load per channel (100 ms windows)" in titles
    assert "NMT state per node" in titles


def test_integer_signals_are_steps_and_scaled_ones_lines(faults_report):
    """Digital inputs and counters hold their value until the next frame (plotly's "hv"
    shape); a scaled temperature is drawn as a line (issue 44: inputs ramped 0 to 1)."""
    _, _, figs = parse(faults_report)
    titles = {f["layout"]["title"]["text"]: f for f in figs.values()}
    shape = {
        (title, d["name"]): d.get("line", {}).get("shape")
        for title, f in titles.items()
        if "PDO" in title
        for d in f["data"]
    }
    assert shape[("Node 6 TPDO1 (0x186)", "di1")] == "hv"
    assert shape[("Node 6 TPDO2 (0x286)", "counter1 (pulses)")] == "hv"
    assert shape[("Node 5 TPDO2 (0x285)", "ch1 (°C)")] is None  # plotly's default: linear
    assert shape[("Node 7 TPDO2 (0x287)", "ai0_i7012 (V)")] is None


def _values(y) -> np.ndarray:
    """A plotly array: a JSON list or a packed array (numpy, from `page_figures`)."""
    return np.asarray(y, float)


def test_report_is_self_contained(faults_report):
    text = faults_report.read_text()
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)
    assert "<link" not in text
    assert faults_report.stat().st_size < 4_000_000


@pytest.mark.slow
def test_page_of_a_long_faulty_log_stays_under_3_mb(tmp_path):
    """Issue 25: a few MB whatever the log's length. The page is plotly.js (fixed), lists
    capped (50 lines per finding group, 2000 EMCYs, 500 SDO aborts) and plots of a fixed
    number of min/max buckets; at 500k frames of the generator's faulty bus every cap is
    reached (asserted), so a longer log adds only finding groups (10M frames: 2.73 MB,
    the same rules). Before the plots were packed it was 4.4 MB."""
    from cananalyze.outputs.report.plots import LINE_BUCKETS, PLOT_BUCKETS

    log = generated_log(tmp_path, 500_000)
    out = tmp_path / "long.html"
    r = cli("report", str(log), "-o", str(out), "-q")
    assert r.returncode == 1, r.stderr
    text, tables, figs = parse(out)
    assert re.search(r"<p class=warn>\d+ more EMCYs not listed</p>", text)
    assert len(re.findall(r"<li>\.\.\. and \d+ more", text)) >= 10
    assert len(table_with(tables, "time", "active for")) - 1 == 2000  # every EMCY a raise
    assert out.stat().st_size < 3_000_000
    # each plot's lines within the budget, the bus load's envelope full (the log is long)
    for f in figs.values():
        lines = [d for d in f["data"] if d.get("mode") == "lines"]
        points = sum(len(d["y"]) for d in lines)
        assert points <= 2 * max(PLOT_BUCKETS, LINE_BUCKETS * len(lines))
    load = next(f for f in figs.values() if f["layout"]["title"]["text"].startswith("Bus load"))
    assert len(load["data"][0]["y"]) > PLOT_BUCKETS
    packed = dict(PACKED.findall(text))
    assert len(packed["figures"].encode()) < 200_000


def test_check_html_and_junit_property(tmp_path):
    import junitparser

    page, junit = tmp_path / "r.html", tmp_path / "j.xml"
    r = cli("check", str(SAMPLES / "faults.log"), "--html", str(page), "--junit", str(junit))
    assert r.returncode == 1
    assert page.stat().st_size > 100_000
    xml = junitparser.JUnitXml.fromfile(str(junit))
    suite = next(iter(xml))
    props = {p.name: p.value for p in suite.properties()}
    assert props == {"cananalyze.report": str(page)}


def test_report_bad_input_one_line(tmp_path):
    r = cli("report", str(tmp_path / "missing.log"), "-o", str(tmp_path / "r.html"))
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "missing.log" in r.stderr
    assert "Traceback" not in r.stderr
    r = cli("report", str(SAMPLES / "faults.log"), "-o", str(tmp_path / "no" / "dir" / "r.html"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert not (tmp_path / "no").exists()


def test_report_separates_channels(tmp_path):
    """A log of two buses: one row and one load trace per channel, counts as python-can reads."""
    lines = []
    for k in range(200):
        t = 1000.0 + k * 0.01
        lines.append(f"({t:.6f}) can0 701#05")
        if k % 2:
            lines.append(f"({t + 0.001:.6f}) can1 705#7F")
    log = tmp_path / "two.log"
    log.write_text("\n".join(lines) + "\n")
    out = tmp_path / "two.html"
    assert cli("report", str(log), "-o", str(out), "--bitrate", "250000").returncode == 0
    _, tables, figs = parse(out)
    with can.LogReader(str(log)) as reader:
        per = {}
        for m in reader:
            per[m.channel] = per.get(m.channel, 0) + 1
    rows = {r[0]: int(r[1]) for r in table_with(tables, "channel", "frames")[1:]}
    assert rows == per == {"can0": 200, "can1": 100}
    load = next(f for f in figs.values() if f["layout"]["title"]["text"].startswith("Bus load"))
    assert [d["name"] for d in load["data"]] == ["can0", "can1"]
    assert load["layout"]["yaxis"]["title"]["text"] == "% of bitrate"


# --- the page's encodings ------------------------------------------------------------


def test_text7_survives_script_text_and_reads_back():
    """Every byte value (and a gzip stream) through `text7`: no character that script
    text changes or that could close it, and the documented decoding gives the bytes."""
    from cananalyze.outputs.report.encode import text7

    rng = np.random.default_rng(3)
    for raw in (bytes(range(256)) * 3, rng.bytes(10_001), b"", b"\x00"):
        text = text7(raw)
        assert "<" not in text and "\r" not in text and "\0" not in text
        assert unpack7(text) == raw
    random = text7(rng.bytes(100_000))  # gzip's output looks random: 1.17 bytes per byte
    assert len(random.encode()) < 100_000 * 8 / 7 * 1.03 < 100_000 * 4 / 3  # base64's


def test_packed_arrays_round_below_a_pixel_and_keep_integers():
    """Plotted values come back within half a step, the step at most 1/3000 of the
    range (a tenth of a pixel on any plot); integers exact; a resolution floor (µs of
    a ms period) removes float noise; both forms (offsets, differences) read back."""
    from cananalyze.outputs.report.encode import Blob, Packed

    rng = np.random.default_rng(5)
    smooth = np.cumsum(rng.normal(size=5000)) * 0.37 + 1e4
    ints = rng.integers(-40_000, 40_000, 3000).astype(float)
    noisy = 100 + rng.choice([0.0, 1.5e-4, 1.0e-4, 2.4e-4], 800)  # epoch time stamps' noise
    times = np.arange(20_000) * 0.18 + 0.05  # an envelope's buckets: steady differences
    huge = np.array([0.0, 5e9, 1e10])  # beyond int32 at µs
    arrays = [Packed(smooth), Packed(ints), Packed(noisy, 1e-3), Packed(times, 1e-6)]
    gap = np.array([1.5, np.nan, 2.25])  # NaN (plotly's gap) as it is
    arrays += [Packed(huge, 1e-6, exact=True), Packed(gap)]
    page = f'<script type="text/plain" id="figures">{Blob().pack([["fig0", arrays]])}</script>'
    back = page_figures(page)["fig0"]
    step = (smooth.max() - smooth.min()) / 3000
    assert np.abs(back[0] - smooth).max() <= step / 2
    assert np.array_equal(back[1], ints)
    assert set(np.round(back[2], 9)) == {100.0}  # was 100.00015 on node 5's axis
    assert np.abs(back[3] - times).max() <= (times.max() - times.min()) / 3000 / 2
    assert np.array_equal(back[4], huge)
    assert np.array_equal(back[5], gap, equal_nan=True)


def test_a_spike_survives_the_plots_point_budget():
    """Envelope.points(most): neighbours merged to the budget, every extreme kept."""
    rng = np.random.default_rng(11)
    t = np.sort(rng.uniform(0, 600, 200_000))
    v = rng.normal(size=t.size)
    v[77_777], v[150_000] = 40.0, -35.0
    env = Envelope()
    env.add(t, v)
    full_t, full_v = env.points()
    for most in (500, 250, 7):
        pt, pv = env.points(most)
        assert pt.size <= 2 * most and np.all(np.diff(pt) >= 0)
        assert pv.max() == 40.0 and pv.min() == -35.0
        assert (
            pt[0] >= full_t[0] - env.width * (1000 / most)
            and pt[-1] <= 600 + env.width * 1000 / most
        )


# --- the accumulators against numpy, every value --------------------------------


def test_envelope_keeps_every_extreme_in_fixed_memory():
    rng = np.random.default_rng(7)
    t = np.sort(rng.uniform(0, 3600, 1_000_000))
    v = rng.normal(size=t.size)
    v[123_456] = 50.0  # one spike
    env = Envelope(buckets=500)
    for a in range(0, t.size, 65_536):
        env.add(t[a : a + 65_536], v[a : a + 65_536])
    pt, pv = env.points()
    assert env.lo.size == 500 and pt.size <= 1000
    assert pv.max() == 50.0 and pv.min() == v.min()
    # each bucket's min and max are those of the values in it
    k = ((t - env.t0) / env.width).astype(int)
    for b in (0, 77, int(k[123_456]), int(k.max())):
        sel = v[k == b]
        assert env.lo[b] == sel.min() and env.hi[b] == sel.max()


def test_window_sums_peak_and_mean():
    t = np.arange(0, 10, 0.001)  # 1 kHz of 100-bit frames, a burst at 5 s
    bits = np.full(t.size, 100.0)
    bits[(t >= 5.0) & (t < 5.1)] = 500.0
    w = WindowSums(0.1)
    for a in range(0, t.size, 777):
        w.add(t[a : a + 777], bits[a : a + 777])
    w.finish()
    assert w.peak == pytest.approx(500 * 100 / 0.1 * 1.0, rel=0.02)
    assert w.mean == pytest.approx(bits.sum() / (t[-1] - t[0]), rel=1e-9)


# --- in a browser -----------------------------------------------------------------


def _browser_check(page: Path, shot_name: str) -> None:
    from helpers import browser

    if browser.chromium() is None:
        pytest.skip("no chromium (Debian's package chromium; .ci/run installs it)")
    pytest.importorskip("websockets")
    from PIL import Image

    v = browser.view(
        page,
        {
            "verdict": "(() => { const e = document.getElementById('verdict-banner');"
            " const r = e.getBoundingClientRect();"
            " return [e.innerText, r.top, r.bottom]; })()",
            "plots": "Array.from(document.querySelectorAll('div.plot')).filter("
            "d => d.querySelector('.main-svg') && d.getBoundingClientRect().top < 900"
            " && d.querySelectorAll('path.js-line, path.point, g.trace').length > 0"
            ").map(d => { const r = d.getBoundingClientRect();"
            " return [r.left, r.top, r.right, Math.min(r.bottom, 900)]; })",
        },
    )
    browser.save_shot(v.screenshot, shot_name)
    assert v.ready, "the plots were not drawn"
    assert v.errors == []
    text, top, bottom = v.answers["verdict"]
    assert text.split()[0] in ("PASS", "FAIL") and 0 <= top and bottom <= 900
    assert v.answers["plots"], "no plot drawn on the first screen"
    img = Image.open(io.BytesIO(v.screenshot)).convert("RGB")
    assert img.size == (1280, 900)
    # the verdict's banner colour is on the screen, and the plot has drawn lines in it
    px = np.asarray(img)
    banner = px[int(top) + 3 : int(bottom) - 3, 40:1200].reshape(-1, 3)
    colours = {(253, 228, 225), (227, 245, 225)}  # fail / pass backgrounds
    assert any((banner == c).all(axis=1).mean() > 0.5 for c in colours)
    left, ptop, right, pbottom = (int(x) for x in v.answers["plots"][0])
    region = px[ptop:pbottom, left:right].reshape(-1, 3).astype(int)
    coloured = (region.max(axis=1) - region.min(axis=1)) > 60  # not white or grey
    assert coloured.sum() > 200


@pytest.mark.slow
def test_report_in_chromium(faults_report):
    _browser_check(faults_report, "faults.png")


READABLE = {
    # each plot's title box and mode bar box (page coordinates)
    "boxes": "Array.from(document.querySelectorAll('div.plot')).map(d => {"
    " const t = d.querySelector('.gtitle'), m = d.querySelector('.modebar');"
    " const box = e => { const r = e.getBoundingClientRect();"
    " return [r.left, r.top + scrollY, r.right, r.bottom + scrollY]; };"
    " return [d.layout.title.text, t ? box(t) : null, m ? box(m) : null]; })",
    # the tick labels of every plot's y axis, by title
    "ticks": "Array.from(document.querySelectorAll('div.plot')).map(d =>"
    " [d.layout.title.text, Array.from(d.querySelectorAll('.ytick text')).map(e => e.textContent)])",
    # what plotly was given (the loader's decoding), by title: each trace's x and y
    "xy": "Array.from(document.querySelectorAll('div.plot')).map(d =>"
    " [d.layout.title.text, d.data.map(t => [Array.from(t.x || []), Array.from(t.y || [])])])",
}


@pytest.mark.slow
def test_report_readable_in_chromium(faults_report):
    """What the eye meets: no plot's title under plotly's mode bar; tick labels without
    float noise (node 5's heartbeat is 100 ms to the µs: its axis read 100.00015); and
    the browser's decoded figures equal the page's documented layout read in Python."""
    from helpers import browser

    if browser.chromium() is None:
        pytest.skip("no chromium (Debian's package chromium; .ci/run installs it)")
    pytest.importorskip("websockets")
    v = browser.view(faults_report, READABLE)
    assert v.ready and v.errors == []
    boxes = v.answers["boxes"]
    assert len(boxes) >= 20 and all(t and m for _, t, m in boxes)
    for title, t, m in boxes:
        apart = t[2] <= m[0] or m[2] <= t[0] or t[3] <= m[1] or m[3] <= t[1]
        assert apart, (title, t, m)
    ticks = dict(v.answers["ticks"])
    assert ticks["Node 5 heartbeat period"]
    for title, labels in ticks.items():
        for label in labels:
            decimals = label.replace("\u2212", "-").partition(".")[2]
            assert len(decimals.rstrip("kMGμm")) <= 3, (title, label)
    _, _, figs = parse(faults_report)
    xy = dict(v.answers["xy"])
    assert len(xy) == len(figs)
    for f in figs.values():
        theirs = xy[f["layout"]["title"]["text"]]
        assert len(theirs) == len(f["data"])
        for d, pair in zip(f["data"], theirs, strict=True):
            for mine, seen in zip((d.get("x", []), d.get("y", [])), pair, strict=True):
                if len(seen) and isinstance(seen[0], str):  # categories (the NMT lanes)
                    assert list(mine) == seen
                else:
                    # NaN: a gap in a line, in both
                    assert np.asarray(seen, float) == pytest.approx(
                        np.asarray(mine, float), nan_ok=True
                    )


@pytest.mark.slow
def test_real_log_report_in_chromium(tmp_path):
    log = real_file("hilch__canopen-message-interpreter/pcan3.trc")
    out = tmp_path / "pcan3.html"
    r = cli("report", str(log), "-o", str(out), "-q")
    assert r.returncode == 1, r.stderr  # the log has SDO aborts and a heartbeat dropout
    _, tables, figs = parse(out)
    assert len([f for f in figs.values() if "heartbeat period" in f["layout"]["title"]["text"]])
    _browser_check(out, "pcan3.png")


def test_a_clock_that_jumps_by_years_costs_nothing(tmp_path):
    """A corrupt time (1e11 s, year 5138) among good frames: the page is written at once,
    every frame counted, the plots keep their fixed number of points."""
    lines = [f"({1000.0 + k * 0.01:.6f}) can0 701#05" for k in range(100)]
    lines.insert(50, "(99999999999.000000) can0 701#05")
    log = tmp_path / "jump.log"
    log.write_text("\n".join(lines) + "\n")
    out = tmp_path / "jump.html"
    r = cli("report", str(log), "-o", str(out), "-q")
    assert r.returncode in (0, 1), r.stderr
    _, tables, figs = parse(out)
    assert table_with(tables, "channel", "frames")[1][1] == "101"
    load = next(f for f in figs.values() if f["layout"]["title"]["text"].startswith("Bus load"))
    assert len(_values(load["data"][0]["y"])) <= 2000


def test_drive_state_section_of_a_real_drive(tmp_path):
    """ZeroErr's enable sequence (remapped TPDO1 carries the statusword): one lane for
    the drive, a bar per state entered, named by the state (as load().drive_states)."""
    import cananalyze

    log = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    out = tmp_path / "drive.html"
    r = cli("report", str(log), "--device", "11=cia402", "-o", str(out), "-q")
    assert r.returncode in (0, 1), r.stderr
    text, _, figs = parse(out)
    assert '<section id="drive">' in text
    fig = next(f for f in figs.values() if f["layout"]["title"]["text"] == "Drive state per node")
    states = cananalyze.load(log, device={11: "cia402"}).drive_states.state.tolist()
    assert states == [
        "switch on disabled",
        "ready to switch on",
        "switched on",
        "operation enabled",
    ]
    assert [d["name"] for d in fig["data"]] == states
    assert all(d["y"] == ["node 11"] for d in fig["data"])


def test_pdo_rates_beside_their_configuration(faults_report):
    """samples/README.md: TPDO2 0x283 inhibit 100 ms and event timer 200 ms, written by the
    master's SDO downloads in the log; TPDO1 0x187 inhibit 20 ms. A 0 only the EDS gives
    is not shown as "off"."""
    _, tables, _ = parse(faults_report)
    pdo = {r[0]: r for r in table_with(tables, "COB-ID", "event timer")[1:]}
    assert pdo["0x283"][9:11] == ["200 ms (log)", "100 ms (log)"]
    assert pdo["0x187"][10] == "20 ms (log)"
    assert not any(v.startswith("off (profile") for r in pdo.values() for v in r[9:11])
    # rates and gaps from every frame (python-can reads them)
    with can.LogReader(str(SAMPLES / "faults.log")) as reader:
        t = np.array([m.timestamp for m in reader if m.arbitration_id == 0x283])
    assert int(pdo["0x283"][3]) == t.size
    assert float(pdo["0x283"][7]) == pytest.approx(np.diff(t).max() * 1000, abs=0.01)


def test_findings_explained_once_per_group(faults_report, tmp_path):
    """Each node-and-rule group lists its findings' lines and each distinct explanation
    once (check --json's `why`), not once per line: the 10M-frame page was half whys."""
    import html as html_mod
    import re

    found = tmp_path / "f.json"
    cli(
        "check",
        str(SAMPLES / "faults.log"),
        *("--network", str(SAMPLES / "network.toml"), "--rules", str(SAMPLES / "rules.yaml")),
        *("--json", str(found), "-q"),
    )
    findings = json.loads(found.read_text())
    page = faults_report.read_text(encoding="utf-8")
    groups = re.findall(r'<details class="finding [^"]*">(.*?)</details>', page, re.S)
    assert len(groups) == len({(f["node"], f["rule"]) for f in findings})
    for body in groups:
        who, rule = re.match(r"<summary><b>(.*?)</b> · (\w+) · ", body).groups()
        mine = [f for f in findings if f["rule"] == rule and who == f"node {f['node']}"] or [
            f for f in findings if f["rule"] == rule and f["node"] is None
        ]
        whys = [html_mod.unescape(w) for w in re.findall(r"<p class=why>(.*?)</p>", body)]
        assert sorted(whys) == sorted({f["why"] for f in mine}), (who, rule)
        items = [html_mod.unescape(i) for i in re.findall(r"<li>(.*?)</li>", body)]
        assert len(items) == len(mine)
        assert not any(f["why"] in i for f in mine for i in items)
        assert {f["message"] for f in mine} == {
            f["message"] for f in mine for i in items if f["message"] in i
        }


def test_a_long_finding_group_lists_fifty_lines_and_counts_the_rest(tmp_path):
    """A rule that fires on every frame: the page lists the first LISTED lines of the
    group and says how many more there are (the count in the summary stays whole)."""
    from cananalyze.outputs.report.sections import LISTED

    log = tmp_path / "sync.log"
    # a SYNC counter jumping on every frame: one finding per SYNC after the first
    log.write_text(
        "".join(f"({k * 0.01:.6f}) can0 080#{(k * 5) % 240 + 1:02X}\n" for k in range(130))
    )
    page = tmp_path / "r.html"
    cli("report", str(log), "-o", str(page))
    html = page.read_text()
    group = html[html.index("· sync ·") :]
    group = group[: group.index("</details>")]
    total = int(re.search(r"(\d+) finding\(s\)", group).group(1))
    counters = [(k * 5) % 240 + 1 for k in range(130)]
    # CiA 301: the counter counts up from 1 and wraps back to 1
    jumps = sum(1 for a, b in zip(counters[:-1], counters[1:], strict=True) if b not in (a + 1, 1))
    assert total == jumps > LISTED
    assert group.count("<li>") == LISTED + 1
    assert f"... and {total - LISTED} more" in group


def test_report_keeps_node_5_of_each_bus_apart(tmp_path):
    """Node 5 on can0 and node 5 on can1 are two devices on the page too: NMT lanes, PDO
    rates, EMCYs (a reset on can0 does not end can1's error) and signal plots per bus;
    frame counts as python-can reads them."""
    lines = []
    for k in range(50):  # 5 s: heartbeats every 100 ms on both buses
        t = 1000.0 + k * 0.1
        lines.append((t, "can0", "705#05"))
        lines.append((t + 0.001, "can1", "705#" + ("7F" if k < 10 else "05")))
        lines.append((t + 0.002, "can0", f"285#{k:02X}00000000000000"))  # TPDO2, 100 ms
        if k >= 10 and k % 5 == 0:  # can1's TPDO2 every 500 ms, once operational
            lines.append((t + 0.003, "can1", f"285#{k:02X}01000000000000"))
    lines.append((1001.5, "can1", "085#0010010000000000"))  # EMCY 0x1000 on can1
    lines.append((1002.5, "can0", "085#0000000000000000"))  # a reset, but on can0
    log = tmp_path / "two5.log"
    log.write_text("".join(f"({t:.6f}) {ch} {f}\n" for t, ch, f in sorted(lines)))
    out = tmp_path / "two5.html"
    r = cli("report", str(log), "-o", str(out), "--device", "5=dat7014", "-q")
    assert r.returncode in (0, 1), r.stderr
    _, tables, figs = parse(out)
    with can.LogReader(str(log)) as reader:
        pdo_frames: dict[str, int] = {}
        for m in reader:
            if m.arbitration_id == 0x285:
                pdo_frames[m.channel] = pdo_frames.get(m.channel, 0) + 1
    pdo = table_with(tables, "COB-ID", "rate Hz")
    head = pdo[0]
    rows = {r[head.index("node")]: r for r in pdo[1:]}
    assert set(rows) == {"can0 node 5", "can1 node 5"}
    for bus, gap in (("can0", 100.0), ("can1", 500.0)):
        row = rows[f"{bus} node 5"]
        assert row[0] == "0x285"
        assert int(row[head.index("frames")].replace(",", "")) == pdo_frames[bus]
        assert float(row[head.index("median gap ms")]) == pytest.approx(gap, abs=0.01)
    lanes = figs_titled(figs, "NMT state per node")
    by_state = {d["name"]: set(d["y"]) for d in lanes["data"]}
    assert by_state["pre-operational"] == {"can1 node 5"}
    assert by_state["operational"] == {"can0 node 5", "can1 node 5"}
    emcy = table_with(tables, "time", "active for")
    (row,) = [r for r in emcy[1:] if r[2] == "0x1000"]
    assert row[1] == "can1 node 5" and row[5] == "still active at the end of the log"
    titles = {f["layout"]["title"]["text"] for f in figs.values()}
    assert {"can0 node 5 TPDO2 (0x285)", "can1 node 5 TPDO2 (0x285)"} <= titles
    assert {"can0 node 5 heartbeat period", "can1 node 5 heartbeat period"} <= titles


def figs_titled(figs: dict, title: str) -> dict:
    return next(f for f in figs.values() if f["layout"]["title"]["text"] == title)


def test_a_log_without_times_orders_emcys_by_line(tmp_path):
    """TMCM-1636's candump screen output has no times: its EMCY 0x6320 at line 102 is
    reset at line 105 (not "still active at the end of the log", which sorting by one
    shared time made it); PDO rates and gaps need times and are not given (issue 44)."""
    tmcm = "nigel-bruce-khan__ros_canopen-tmcm-1636/"
    out = tmp_path / "tmcm.html"
    dcf = real_file(tmcm + "TMCM-1636-CANopen.dcf")
    r = cli("report", str(real_file(tmcm + "candump.txt")), "--eds", f"1={dcf}", "-o", str(out))
    assert r.returncode == 1, r.stderr
    text, tables, _ = parse(out)
    emcy = table_with(tables, "time", "active for")
    assert len(emcy) == 2
    assert emcy[1][0] == "line 102" and emcy[1][2] == "0x6320"
    assert emcy[1][5] == "reset at line 105"
    assert "still active at the end of the log" not in text
    pdo = table_with(tables, "COB-ID", "rate Hz")
    rpdo3 = next(row for row in pdo if row[0] == "0x401")
    assert rpdo3[4:8] == ["-", "-", "-", "-"]


def test_pdo_settings_nothing_configured_are_not_known(tmp_path):
    """pcan3's node 85: no network file, no EDS, no SDO write of its TPDO timers: the PDO
    table says it does not know them, not "off (network file)" (issue 44)."""
    out = tmp_path / "pcan3.html"
    log = real_file("hilch__canopen-message-interpreter/pcan3.trc")
    assert cli("report", str(log), "-o", str(out), "-q").returncode == 1
    text, tables, _ = parse(out)
    pdo = table_with(tables, "COB-ID", "event timer")
    head = pdo[0]
    row = next(r for r in pdo if r[0] == "0x1D5")
    assert row[head.index("event timer")] == "not known"
    assert row[head.index("inhibit time")] == "not known"
    assert "(network file)" not in text and "configured not configured" not in text
