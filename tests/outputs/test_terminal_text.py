"""Issue 38 item 1, terminals: a name from a log, an EDS, a DBC, a network or a rules file
reaches decode's lines, the summary, check's findings and `devices` as text, its control
characters shown as escapes (\\x1b), never obeyed: an escape sequence in a channel's name
retitled, recoloured or cleared the user's terminal, a carriage return forged a line.
The same inputs as the report's injection tests, with terminal payloads."""

from __future__ import annotations

import json
import re

import pytest
from conftest import ROOT

from tests.outputs.test_report_injection import DBC, _candump, _toml, cli

# OSC title, clear screen, a one-character CSI (C1), a carriage return, a bell
TITLE = "\x1b]0;pwned\x07"
CLEAR = "\x1b[2J\x1b[H"
CSI = "\x9b31m"
CR = "x\rforged"
CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f]")  # all but the line ends


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("terminal")
    dbc = d / "payload.dbc"
    dbc.write_text(
        DBC.format(unit1=TITLE, unit2=CSI, bold=CLEAR, name1="S" + CR, name2=CSI, p1=CR, p3=TITLE)
    )
    eds_text = (ROOT / "decoders" / "dat7130.eds").read_text()
    eds_text = eds_text.replace("ProductName=DAT 7130", f"ProductName={TITLE}")
    eds_text = eds_text.replace("ParameterName=Manufacturer device name", f"ParameterName={CLEAR}")
    eds = d / "payload.eds"
    eds.write_text(eds_text)
    network = d / "network.toml"
    network.write_text(
        "[nodes.5]\n"
        'device = "dat7014"\n'
        f"name = {_toml(CSI)}\n"
        "[nodes.5.signals]\n"
        f'"6401:01" = {{ name = {_toml(CR)}, unit = {_toml(TITLE)} }}\n'
    )
    rules = d / "rules.yaml"
    rules.write_text(
        "assert:\n"
        f"  - signal: {{node: 5, signal: {json.dumps(CR)}, min: 0, max: 1}}\n"
        "  - heartbeat: {node: 5, period_ms: 100}\n"
    )
    chan = "ca" + TITLE  # no white space: a candump channel token
    lines = [(1000.0, chan, "705#00"), (1000.001, chan, "706#00")]
    lines.append((1000.05, chan, "000#0100"))
    for k in range(30):
        t = 1000.1 + k * 0.1
        lines += [(t, chan, "705#05"), (t + 0.001, chan, "706#05")]
        lines.append((t + 0.002, chan, f"285#{k:02X}00{k:02X}0000000000"))
        lines.append((t + 0.003, chan, "10A#0010002803001000"))
    lines.append((1001.5, chan, "606#4008100000000000"))  # 0x1008 upload, aborted
    lines.append((1001.501, chan, "586#8008100000000206"))
    log = _candump(d / "files.log", lines)
    files = ("--dbc", str(dbc), "--eds", f"6={eds}", "--network", str(network))
    return log, files, rules, eds


def _clean(text: str, what: str) -> None:
    bad = CONTROL.search(text)
    assert bad is None, (
        f"{what}: {bad.group()!r} at {text[max(bad.start() - 40, 0) : bad.end() + 10]!r}"
    )


def test_decode_lines_and_summary_show_control_characters_as_escapes(inputs):
    log, files, _, _ = inputs
    r = cli("decode", str(log), *files)
    assert r.returncode in (0, 1), r.stderr
    _clean(r.stdout + r.stderr, "decode")
    assert "ca\\x1b]0;pwned\\x07" in r.stdout  # the channel, shown
    assert "\\x1b[2J" in r.stdout  # the EDS's name of 0x1008, in the abort's line
    s = cli("decode", str(log), *files, "--summary")
    _clean(s.stdout + s.stderr, "summary")


def test_check_findings_show_control_characters_as_escapes(inputs):
    log, files, rules, _ = inputs
    r = cli("check", str(log), *files, "--rules", str(rules), "--timing")
    assert r.returncode in (0, 1), r.stderr
    _clean(r.stdout + r.stderr, "check")
    assert "x\\x0dforged" in r.stdout  # the signal's name, in its assertion's finding


def test_devices_shows_an_eds_names_as_escapes(inputs):
    *_, eds = inputs
    r = cli("devices", str(eds))
    assert r.returncode == 0, r.stderr
    _clean(r.stdout + r.stderr, "devices")
    assert "\\x1b]0;pwned\\x07" in r.stdout
