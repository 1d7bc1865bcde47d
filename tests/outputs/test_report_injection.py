"""The report's page is escaped by construction: markup in any text that reaches it (a
channel's name, the log's file name, --title, DBC, EDS, network and rules files) stays
text, in the HTML (parsed with html.parser), in the plots' figures and in Chromium
(issue 38: a channel's name ran its script in the browser)."""

from __future__ import annotations

import html
import json
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest
from conftest import ROOT

from tests.outputs.test_report import page_figures, parse, table_with

# each sets window.__pwned where markup from the input becomes elements or script
P1 = "<script>window.__pwned=1</script>"
P2 = '"><img src=x onerror="window.__pwned=2">'
P3 = "</script><script>window.__pwned=3</script>"
QUOTES = "'\""
# a channel's name has no white space: the attribute breakout without a space
P2_CHANNEL = '"><svg/onload=window.__pwned=2>'
CHANNELS = (P1, P2_CHANNEL, P3 + QUOTES)
LOG_NAME = '"><img src=x onerror="window.__pwned=4">.log'  # no "/" in a file name
TITLE = "</title><script>window.__pwned=5</script>" + QUOTES
P7 = "</script><script>window.__pwned=7</script>"  # an EDS's parameter name
EDS_NAME = '"><img src=x onerror="window.__pwned=6">.eds'
BOLD = "<b>B</b><br>"  # plotly's own markup: in a figure's text it must stay text too

# what the page itself is made of: anything else came from the input
TAGS = {"html", "head", "meta", "title", "style", "script", "body", "h1", "h2", "h3", "p"}
TAGS |= {"nav", "a", "section", "div", "b", "table", "thead", "tbody", "tr", "th", "td"}
TAGS |= {"details", "summary", "ul", "li", "code"}
TAGS |= {"svg", "defs", "marker", "path", "line", "circle", "text"}  # the network page
ATTRS = {"lang", "charset", "type", "id", "class", "href"}
ATTRS |= {"width", "height", "viewbox", "role", "aria-label", "refx", "refy", "markerwidth"}
ATTRS |= {"markerheight", "orient", "d", "fill", "x1", "y1", "x2", "y2", "marker-end"}
ATTRS |= {"x", "y", "cx", "cy", "r"}
SCRIPTS = 3  # plotly.js and the figures (both packed text), the loader


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )


def _candump(path: Path, lines: list[tuple[float, str, str]]) -> Path:
    path.write_text("".join(f"({t:.6f}) {ch} {f}\n" for t, ch, f in sorted(lines)))
    return path


@pytest.fixture(scope="module")
def channels_page(tmp_path_factory) -> tuple[Path, str]:
    """Three buses named by the payloads, each with node 5 (labels "{bus} node 5" in the
    node ids, the tables and the plots): heartbeats, PDOs, an EMCY and an SDO abort;
    the log's file name a payload too (its title and the line under it)."""
    d = tmp_path_factory.mktemp("inject")
    lines = []
    for k in range(40):
        t = 1000.0 + k * 0.1
        for c, ch in enumerate(CHANNELS):
            tt = t + c * 0.002
            if k == 0:
                lines.append((tt, ch, "705#00"))
            lines.append((tt + 0.0005, ch, "705#" + ("7F" if k < 5 else "05")))
            lines.append((tt + 0.001, ch, f"285#{k:02X}00000000000000"))
            if k == 20:
                lines.append((tt + 0.0015, ch, "085#0010010000000000"))
                lines.append((tt + 0.0016, ch, "605#4000200000000000"))
                lines.append((tt + 0.0017, ch, "585#8000200000000206"))
    try:
        log = _candump(d / LOG_NAME, lines)
    except OSError:  # a file system without '"', '<' or '>' in names
        log = _candump(d / "channels.log", lines)
    out = d / "channels.html"
    r = cli("report", str(log), "--device", "5=dat7014", "-o", str(out), "-q")
    assert r.returncode in (0, 1), r.stderr
    return out, log.name


DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 266 Engine: 8 ECU
 SG_ rpm : 7|16@0+ (0.25,0) [0|16383.75] "{unit1}" ECU
 SG_ gear : 24|3@1+ (1,0) [0|7] "{unit2}" ECU
 SG_ temp : 16|8@1- (1,-40) [-168|87] "{bold}" ECU

BA_DEF_ SG_ "SystemSignalLongSymbol" STRING ;
BA_DEF_DEF_ "SystemSignalLongSymbol" "";
BA_ "SystemSignalLongSymbol" SG_ 266 rpm "{name1}";
BA_ "SystemSignalLongSymbol" SG_ 266 temp "{name2}";
VAL_ 266 gear 0 "{p1}" 1 "{p3}" 3 "drive" ;
"""


def _toml(s: str) -> str:
    return json.dumps(s)  # a JSON string of ASCII is a TOML basic string


@pytest.fixture(scope="module")
def files_page(tmp_path_factory) -> tuple[Path, str]:
    """One bus: --title; a DBC's signal names (long symbols: a message's name is an
    identifier), units and value tables; an EDS's product, vendor and parameter names
    (0x1008's, which an SDO abort names) and its file name (the node's device); the
    network file's node name and its signals' names and units; a rules file's signal
    assertion (its name in the finding's message). Some of them (the value tables, the
    EDS's product and vendor, the node's name) appear nowhere on the page today: the
    page is checked all the same."""
    d = tmp_path_factory.mktemp("inject")
    dbc = d / "payload.dbc"
    dbc.write_text(
        DBC.format(
            unit1=P1, unit2="'" + P3, bold=BOLD, name1="S" + P1, name2=P3, p1=P1, p3=P3 + "'"
        )
    )
    eds_text = (ROOT / "decoders" / "dat7130.eds").read_text()
    eds_text = eds_text.replace("ProductName=DAT 7130", f"ProductName={P1}")
    eds_text = eds_text.replace("VendorName=Datexel s.r.l.", f"VendorName={P2}")
    eds_text = eds_text.replace("ParameterName=Manufacturer device name", f"ParameterName={P7}")
    try:
        eds = d / EDS_NAME
        eds.write_text(eds_text)
    except OSError:
        eds = d / "payload.eds"
        eds.write_text(eds_text)
    network = d / "network.toml"
    network.write_text(
        "[nodes.5]\n"
        'device = "dat7014"\n'
        f"name = {_toml(P2)}\n"
        "[nodes.5.signals]\n"
        f'"6401:01" = {{ name = {_toml(P1)}, unit = {_toml(BOLD)} }}\n'
        f'"6401:02" = {{ name = {_toml(P2)}, unit = {_toml(P3 + QUOTES)} }}\n'
    )
    rules = d / "rules.yaml"
    rules.write_text(
        "assert:\n"
        f"  - signal: {{node: 5, signal: {json.dumps(P3 + QUOTES)}, min: 0, max: 1}}\n"
        "  - heartbeat: {node: 5, period_ms: 100}\n"
    )
    lines = [(1000.0, "can0", "705#00"), (1000.001, "can0", "706#00")]
    lines.append((1000.05, "can0", "000#0100"))
    for k in range(30):
        t = 1000.1 + k * 0.1
        lines += [(t, "can0", "705#05"), (t + 0.001, "can0", "706#05")]
        lines.append((t + 0.002, "can0", f"285#{k:02X}00{k:02X}0000000000"))
        lines.append((t + 0.003, "can0", "10A#0010002803001000"))
    lines.append((1001.5, "can0", "606#4008100000000000"))  # 0x1008 upload, aborted
    lines.append((1001.501, "can0", "586#8008100000000206"))
    lines.append((1001.6, "can0", "086#0010010000000000"))  # an EMCY of node 6
    log = _candump(d / "files.log", lines)
    out = d / "files.html"
    r = cli(
        "report",
        str(log),
        *("--title", TITLE, "--dbc", str(dbc), "--eds", f"6={eds}"),
        *("--network", str(network), "--rules", str(rules), "-o", str(out), "-q"),
    )
    assert r.returncode in (0, 1), r.stderr
    return out, eds.stem


class Elements(HTMLParser):
    """Every start tag with its attributes, and the text of each element outside scripts."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict]] = []
        self.text: list[str] = []
        self._in: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))
        self._in.append(tag)

    def handle_startendtag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    def handle_endtag(self, tag):
        if tag in self._in:
            del self._in[len(self._in) - 1 - self._in[::-1].index(tag) :]

    def handle_data(self, data):
        if "script" not in self._in and "style" not in self._in:
            self.text.append(data)


def _elements(page: Path) -> Elements:
    p = Elements()
    p.feed(page.read_text(encoding="utf-8"))
    p.close()
    return p


def _assert_inert(page: Path, shown: list[str]) -> None:
    """No element or attribute but the page's own; every id a slug, once; each text of
    `shown` in the page's text as it was given."""
    p = _elements(page)
    tags = [t for t, _ in p.tags]
    assert set(tags) <= TAGS, set(tags) - TAGS
    assert tags.count("script") == SCRIPTS
    for tag, attrs in p.tags:
        assert set(attrs) <= ATTRS, (tag, attrs)
        if tag == "script":
            assert attrs in (
                {"type": "text/plain", "id": "plotlyjs"},
                {},
                {"type": "text/plain", "id": "figures"},
            )
    ids = [a["id"] for _, a in p.tags if "id" in a]
    assert len(ids) == len(set(ids))
    assert all(re.fullmatch(r"[A-Za-z0-9_-]+", i) for i in ids), ids
    hrefs = [a["href"] for _, a in p.tags if "href" in a]
    assert all(h[1:] in ids for h in hrefs), hrefs
    text = "".join(p.text)
    for s in shown:
        assert s in text, s


def _figure_texts(page: Path) -> list[str]:
    """The text plotly draws of each figure: titles, axis titles, trace names, category
    values (the lanes) and hover templates."""
    out = []
    for fig in page_figures(page.read_text(encoding="utf-8")).values():
        lay = fig["layout"]
        out.append(lay["title"]["text"])
        out += [lay[a]["title"]["text"] for a in ("xaxis", "yaxis")]
        for tr in fig["data"]:
            out += [tr.get("name", ""), tr.get("hovertemplate", "")]
            for k in ("x", "y"):
                v = tr.get(k)
                if isinstance(v, list):
                    out += [c for c in v if isinstance(c, str)]
    return out


def _assert_figures_plain(page: Path, shown: list[str]) -> None:
    """plotly reads <b>, <br>, <a> and more in its texts: input-derived text comes as
    entities (plotly shows them as the characters), so no tag but our own <extra>."""
    texts = _figure_texts(page)
    for t in texts:
        assert "<" not in t.replace("<extra></extra>", ""), t
    joined = "\n".join(html.unescape(t) for t in texts)
    for s in shown:
        assert s in joined, s


def test_channel_names_and_log_name_stay_text(channels_page):
    page, log_name = channels_page
    # the buses table, the findings, the node sections, the EMCY, SDO and PDO tables
    shown = [*CHANNELS, *(f"{c} node 5" for c in CHANNELS), log_name]
    _assert_inert(page, shown)
    _assert_figures_plain(page, [*CHANNELS, f"{CHANNELS[1]} node 5"])
    # each bus's node 5 keeps its own section, under an id of its own
    text, tables, _ = parse(page)
    assert len(re.findall(r'<div class="node" id="node-[A-Za-z0-9_-]+-5">', text)) == 3
    # the "{bus} node 5" labels in the table cells, as text
    labels = {f"{c} node 5" for c in CHANNELS}
    for first, header, column in (
        ("time", "active for", 1),  # EMCY
        ("COB-ID", "rate Hz", 1),  # PDO rates
        ("node", "transfers", 0),  # SDO
        ("time", "code", 1),  # SDO aborts
    ):
        rows = table_with(tables, first, header)[1:]
        assert {r[column] for r in rows} == labels, header
    assert {r[0] for r in table_with(tables, "channel", "frames")[1:]} == set(CHANNELS)


def test_file_texts_stay_text(files_page):
    page, eds_stem = files_page
    # the title, the rules' signal (a finding), 0x1008's name (an SDO abort), node 6's
    # device (the EDS's name)
    _assert_inert(page, [TITLE, P3 + QUOTES, P7, eds_stem])
    _assert_figures_plain(page, [P1, P2, BOLD, P3 + QUOTES, "S" + P1])


def _in_chromium(page: Path, shown: list[str]):
    from helpers import browser

    if browser.chromium() is None:
        pytest.skip("no chromium (Debian's package chromium; .ci/run installs it)")
    pytest.importorskip("websockets")
    v = browser.view(
        page,
        {
            "pwned": "String(window.__pwned)",
            "title": "document.title",
            "text": "document.body.innerText",
            "plots": "Array.from(document.querySelectorAll('div.plot')).map(d =>"
            " Array.from(d.querySelectorAll('.gtitle, .legendtext, .g-ytitle'))"
            ".map(e => e.textContent).join('\\n')).join('\\n')",
        },
    )
    assert v.ready, "the plots were not drawn"
    assert v.answers["pwned"] == "undefined"
    assert v.errors == []  # no image failed to load, no script ran
    for s in shown:
        assert s in v.answers["text"], s
    return v


@pytest.mark.slow
def test_channel_names_inert_in_chromium(channels_page):
    page, log_name = channels_page
    v = _in_chromium(page, [*CHANNELS, f"{CHANNELS[2]} node 5", log_name])
    assert v.answers["title"] == f"cananalyze report: {page.parent / log_name}"
    assert P1 in v.answers["plots"]  # a bus load trace's legend, as it was given


@pytest.mark.slow
def test_file_texts_inert_in_chromium(files_page):
    v = _in_chromium(files_page[0], [TITLE, P3 + QUOTES, P7])
    assert v.answers["title"] == TITLE
    for s in (BOLD, P1, P3 + QUOTES):  # signal names and units: legends, axis titles
        assert s in v.answers["plots"], s
