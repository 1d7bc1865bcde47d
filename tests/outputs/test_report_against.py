"""`report LOG --against B`: the page's Differences section names what `diff LOG B`
names (its --json read as the reference), says so when there is nothing, and keeps an
EDS's hostile object name as text (the page parsed with html.parser)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import ROOT, SAMPLES

from tests.outputs.test_report import cli, parse, table_with
from tests.outputs.test_report_injection import P1, _assert_inert, _in_chromium

NETWORK = SAMPLES / "network.toml"


def _report(tmp: Path, log: Path, b: Path, *more: str) -> tuple[str, list[list[str]] | None]:
    out = tmp / "report.html"
    r = cli("report", str(log), "--against", str(b), *more, "-o", str(out), "-q")
    assert r.returncode in (0, 1), r.stderr
    text, tables, _ = parse(out)
    try:
        rows = table_with(tables, "node", "this log")[1:]
    except AssertionError:
        rows = None
    return text, rows


def _who(node: str) -> str:
    bus, _, n = node.rpartition("/")
    return node if node == "network" else f"{bus} node {n}".lstrip()


def test_each_difference_diff_names_is_in_the_report(tmp_path):
    a, b = SAMPLES / "commissioning.log", SAMPLES / "faults.log"
    d = cli("diff", str(a), str(b), "--network", str(NETWORK), "--json", "-")
    assert d.returncode == 1, d.stderr
    named = json.loads(d.stdout)["differences"]
    assert len(named) > 20
    text, rows = _report(tmp_path, a, b, "--network", str(NETWORK))
    assert f"{len(named)} difference(s)" in text
    assert rows is not None and len(rows) == len(named)
    got = [(r[0], r[1], r[2]) for r in rows]
    for n in named:
        if n["section"] == "nodes":
            continue
        assert (_who(n["node"]), n["section"], n["item"]) in got, n
    # the values as diff gives them: a rate of node 3's TPDO, EMCY codes only in B
    emcy = [r for r in rows if r[1] == "emcy"]
    assert emcy and all(r[3] == "(none)" and r[4].startswith("0x") for r in emcy)


def test_a_log_against_itself_has_no_differences(tmp_path):
    log = SAMPLES / "commissioning.log"
    text, rows = _report(tmp_path, log, log)
    assert rows is None
    assert 'id="differences"' in text and "no differences." in text


@pytest.fixture(scope="module")
def hostile_page(tmp_path_factory) -> tuple[Path, str, list]:
    """Node 5's heartbeat time written (1000 ms), its EDS naming 0x1017 with a script; B a
    DCF of that EDS giving 250 ms: the difference's item carries the name."""
    tmp = tmp_path_factory.mktemp("against")
    eds_text = (ROOT / "decoders" / "dat7130.eds").read_text()
    eds_text = eds_text.replace("ParameterName=Producer heartbeat time", f"ParameterName={P1}")
    eds = tmp / "payload.eds"
    eds.write_text(eds_text)
    dcf = tmp / "payload.dcf"
    head, sep, tail = eds_text.partition("[1017]")
    dcf.write_text(head + sep + tail.replace("PDOMapping=0", "ParameterValue=250\nPDOMapping=0", 1))
    log = tmp / "hb.log"
    log.write_text(
        "(1000.000000) can0 705#00\n"
        "(1000.100000) can0 605#2B171000E8030000\n"
        "(1000.101000) can0 585#6017100000000000\n"
        "(1000.200000) can0 705#05\n"
    )
    text, rows = _report(tmp, log, dcf, "--eds", f"5={eds}", "--ref-node", "5")
    return tmp / "report.html", text, rows


def test_a_hostile_object_name_stays_text(hostile_page):
    page, text, rows = hostile_page
    assert rows == [["node 5", "configuration", f"0x1017:00 {P1}", "1000", "250"]]
    assert P1 not in text  # only as entities in the HTML
    _assert_inert(page, [f"0x1017:00 {P1}"])


@pytest.mark.slow
def test_a_hostile_object_name_inert_in_chromium(hostile_page):
    _in_chromium(hostile_page[0], [f"0x1017:00 {P1}"])


def test_against_needs_a_file_not_stdin(tmp_path):
    r = cli("report", "-", "--against", str(SAMPLES / "demo.log"), "-o", str(tmp_path / "x.html"))
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "stdin" in r.stderr


@pytest.mark.parametrize("missing", ["nothere.log", "nothere.dcf"])
def test_a_missing_b_is_one_line(tmp_path, missing):
    r = cli(
        "report",
        str(SAMPLES / "demo.log"),
        "--against",
        str(tmp_path / missing),
        "-o",
        str(tmp_path / "x.html"),
        "-q",
    )
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and missing in r.stderr, r.stderr
