"""`check --json` and `--junit` on a faulty bus: streamed a chunk of findings at a time,
byte for byte what one `json.dumps(records, indent=1)` and one ElementTree of every
finding gave, with a peak memory that does not grow with the number of findings (they
held every record or Finding and the whole text: ~2 GB at 10M faulty frames). Read back
with `json` and junitparser; the peak measured on the command line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import tracemalloc
import xml.etree.ElementTree as ET

import junitparser
import numpy as np
import pytest
from conftest import ROOT, SAMPLES, generated_log

from cananalyze.core.atomic import Staged
from cananalyze.core.finding import Finding
from cananalyze.core.finding_columns import FindingColumns
from cananalyze.outputs.findings import FindingsSink
from cananalyze.outputs.findings_json import findings_json_parts
from cananalyze.outputs.junit import _subject, format_finding, junit_xml, junit_xml_parts
from cananalyze.pipeline import Options, build_checker, build_decoder, open_source, run


def _reference(found) -> str:
    """The text as it was built before: every record, one json.dumps."""
    records = found.records() if isinstance(found, FindingColumns) else [f.record() for f in found]
    return json.dumps(records, indent=1) + "\n"


def _junit_reference(rules, findings, name="cananalyze check", properties=None) -> str:
    """The JUnit text as it was built before: a Finding per row, one ElementTree."""
    cases: dict[str, list[Finding]] = {}
    for rule in rules:
        for s in sorted(rule.subjects or {None}, key=lambda x: (x is not None, x or 0)):
            cases.setdefault(_subject(rule, s), [])
    by_rule = {r.name: r for r in rules}
    for f in findings:
        rule = by_rule.get(f.rule)
        key = f.cob_id if rule and rule.name in ("assert_pdo_rate", "unknown_cob_id") else f.node
        cases.setdefault(_subject(rule, key, f.bus) if rule else f.rule, []).append(f)
    failing = sum(1 for fs in cases.values() if any(f.fails for f in fs))
    suite = ET.Element("testsuite", name=name, tests=str(len(cases)), failures=str(failing),
                       errors="0")  # fmt: skip
    if properties:
        props = ET.SubElement(suite, "properties")
        for key, value in properties.items():
            ET.SubElement(props, "property", name=key, value=value)
    for case, fs in cases.items():
        tc = ET.SubElement(suite, "testcase", classname=f"cananalyze.{case.split()[0]}", name=case)
        bad = [f for f in fs if f.fails]
        if bad:
            fail = ET.SubElement(tc, "failure", message=f"{len(bad)} finding(s): {bad[0].message}",
                                 type=bad[0].severity)  # fmt: skip
            fail.text = "\n".join(format_finding(f) for f in bad)
        info = [f for f in fs if not f.fails]
        if info:
            ET.SubElement(tc, "system-out").text = "\n".join(format_finding(f) for f in info)
    root = ET.Element("testsuites")
    root.append(suite)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


@pytest.fixture(scope="module")
def checked() -> tuple[FindingColumns, list]:
    """The findings of the faulty sample with its network and rules files, and the rules."""
    opts = Options(network=SAMPLES / "network.toml", rules=SAMPLES / "rules.yaml")
    sink = FindingsSink(quiet=True)
    run(open_source(SAMPLES / "faults.log", opts), build_decoder(opts, build_checker(opts)),
        [sink], opts)  # fmt: skip
    assert len(sink.findings) >= 10  # 16: several chunks of 7
    return sink.findings, sink.run.checker.rules


@pytest.fixture(scope="module")
def faults(checked) -> FindingColumns:
    return checked[0]


# as long as a rule's: a line of JUnit is mostly this
WHY = "A jump in the counter means lost frames or a second producer; check the producer."


def _many(n: int = 10_000) -> FindingColumns:
    """Findings of every value shape: ranges (lists), floats, None, several buses, rows
    emitted alone (their Finding object), lazily built messages, a non-ASCII text."""
    t = 1767225600.0 + np.arange(n) * 0.001
    block = FindingColumns.block(
        "sync", ["error", "warning", "info"] * (n // 3) + ["error"] * (n % 3), t,
        np.arange(n) % 5, 0x080, lambda idx: [f"counter {i} jumped, ±{i % 7} <&>" for i in idx],
        [[i * 0.1, i + 0.5] if i % 4 == 0 else (None if i % 4 == 1 else i * 1.1)
         for i in range(n)],
        [i if i % 2 else "x\ty\"z" for i in range(n)], WHY, basis="learned",
    )  # fmt: skip
    block.t_rel[:] = t - t[0]
    block.bus[::3] = "can1"
    alone = [
        Finding(t[0] + k, "heartbeat", "error", 3, None, f"silent {k}", 1.5, [0.1, 0.2],
                line=k, at_end=True)
        for k in range(50)
    ]  # fmt: skip
    m = min(n, 40)
    cob = FindingColumns.block(
        "unknown_cob_id", "warning", t[:m] + 0.0005, None, 0x181 + np.arange(m) % 3,
        [f"0x{0x181 + k % 3:03X} <unknown>" for k in range(m)], 1, 0, "no such PDO",
    )  # fmt: skip
    mine = FindingColumns.block("my_rule", "info", t[:5], 9, None, ["x > 1"] * 5, 2, 1, "")
    return FindingColumns.concat([block, FindingColumns.of(alone), cob, mine])


@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_streamed_json_is_the_same_bytes_for_the_faulty_sample(faults, chunk):
    text = "".join(findings_json_parts(faults, chunk=chunk))
    assert text == _reference(faults)
    assert json.loads(text) == faults.records()


@pytest.mark.parametrize("chunk", [1, 999, 4096, 100_000])
def test_streamed_json_is_the_same_bytes_for_many_findings(chunk):
    many = _many()
    text = "".join(findings_json_parts(many, chunk=chunk))
    assert text == _reference(_many())
    got = json.loads(text)
    assert len(got) == 10_095 and got == json.loads(json.dumps(_many().records()))
    assert got[10_049]["message"] == "silent 49" and got[10_049]["line"] == 49
    assert got[0]["measured"] == [0.0, 0.5] and got[3]["bus"] == "can1" and "bus" not in got[1]


def test_streamed_json_of_finding_objects_and_of_none():
    fs = _many(30).findings()
    assert "".join(findings_json_parts(fs, chunk=4)) == _reference(fs)
    assert "".join(findings_json_parts(fs)) == _reference(fs)
    assert "".join(findings_json_parts([])) == json.dumps([], indent=1) + "\n" == "[]\n"
    assert "".join(findings_json_parts(FindingColumns())) == "[]\n"


def _writing_peak(found: FindingColumns, dest) -> int:
    """Peak bytes of Python objects while `found` is encoded and written (500 at a time)."""
    found.messages()  # built beforehand: the findings' own memory, not the writing's
    staged = Staged(dest)
    tracemalloc.start()
    try:
        staged.write_text(findings_json_parts(found, chunk=500))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    staged.commit()
    assert dest.read_text() == _reference(found)
    return peak


@pytest.mark.slow
def test_json_writing_holds_a_chunk_not_the_text(tmp_path):
    """Four times the findings, about the same peak while writing them, well under the
    file's size (the text built at once held more than the file)."""
    small = _writing_peak(_many(5_000), tmp_path / "small.json")
    big = _writing_peak(_many(20_000), tmp_path / "big.json")
    size = (tmp_path / "big.json").stat().st_size
    assert big < 1.3 * small and big < size / 3, (small, big, size)


def _peak_rss_kb(args: list[str]) -> int:
    """Maximum resident set size of one `cananalyze` child process (from wait4)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "cananalyze", *args], cwd=ROOT, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    _, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode()
    proc.stderr.close()
    assert os.waitstatus_to_exitcode(status) == 1, err  # violations found
    return usage.ru_maxrss


@pytest.mark.slow
def test_check_json_peak_memory_does_not_grow_with_the_findings(tmp_path):
    """What --json adds to check's peak RSS, on a faulty log and on one 4x longer: it
    grew by about 8x the extra JSON text (every record and the text held at once); now
    by less than half of it (one chunk at a time)."""
    added, size = [], []
    for frames in (100_000, 400_000):
        log = generated_log(tmp_path, frames)
        out = tmp_path / f"f{frames}.json"
        plain = _peak_rss_kb(["check", str(log), "-q"])
        with_json = _peak_rss_kb(["check", str(log), "-q", "--json", str(out)])
        added.append((with_json - plain) * 1024)
        size.append(out.stat().st_size)
        assert json.loads(out.read_text())[-1]["kind"] == "finding"
    assert size[1] > 3 * size[0] > 10_000_000  # 4x the findings: ~5.6 and ~22 MB
    assert added[1] - added[0] < (size[1] - size[0]) / 2, (added, size)


def test_json_to_a_full_disk_names_the_file():
    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(SAMPLES / "faults.log"), "-q",
         "--network", str(SAMPLES / "network.toml"), "--json", "/dev/full"],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        "cananalyze: error: /dev/full: No space left on device"
    )


def test_json_to_a_fifo_is_written_at_commit_and_not_on_abort(tmp_path, faults):
    """A special file is written only at commit (all or nothing), the pieces produced
    then; an aborted run never starts producing them."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    produced = []

    def parts():
        for piece in findings_json_parts(faults, chunk=5):
            produced.append(len(piece))
            yield piece

    dropped = Staged(fifo)
    dropped.write_text(parts())
    dropped.abort()
    dropped.commit()  # nothing left to write: no open of the FIFO (it would block)
    assert produced == []

    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    staged = Staged(fifo)
    staged.write_text(parts())
    assert produced == []
    staged.commit()
    reader.join(10)
    assert got == [_reference(faults)] and len(produced) > 2


@pytest.mark.parametrize("chunk", [1, 3, 4096])
def test_streamed_junit_is_the_same_bytes_for_the_faulty_sample(checked, chunk, monkeypatch):
    found, rules = checked
    monkeypatch.setattr("cananalyze.outputs.junit.CHUNK", chunk)
    props = {"cananalyze.report": "r&<report>.html"}
    text = "".join(junit_xml_parts(rules, found, properties=props))
    assert text == _junit_reference(rules, found.findings(), properties=props)
    suites = junitparser.JUnitXml.fromstring(text.split("?>", 1)[1])
    suite = next(iter(suites))
    failed = [c for c in suite if c.result]
    assert suite.failures == len(failed) > 3 and suite.tests == len(list(suite))


@pytest.mark.parametrize("chunk", [1, 999, 4096])
def test_streamed_junit_is_the_same_bytes_for_many_findings(checked, chunk, monkeypatch):
    """Several buses, rows emitted alone, per-COB-ID cases, a rule no checker has, text
    that must be escaped; cases first named by a finding, in the order they come."""
    rules = checked[1]
    monkeypatch.setattr("cananalyze.outputs.junit.CHUNK", chunk)
    many = _many()
    text = "".join(junit_xml_parts(rules, many, name="many"))
    assert text == _junit_reference(rules, _many().findings(), name="many")
    suite = next(iter(junitparser.JUnitXml.fromstring(text.split("?>", 1)[1])))
    names = [c.name for c in suite]
    assert {"sync node 1", "sync can1 node 1", "unknown_cob_id 0x182", "my_rule"} <= set(names)
    sync = [c for c in suite if c.name.startswith("sync ")]
    failed = [line for c in sync if c.result for line in c.result[0].text.split("\n")]
    assert len(failed) == sum(1 for i in range(10_000) if i % 3 != 2)  # errors, warnings
    assert "jumped, ±1 <&>" in failed[1] and failed[1].endswith(WHY)
    assert sum(len(c.system_out.split("\n")) for c in sync if c.system_out) == 3333  # info


def test_junit_of_finding_objects_and_of_none(checked):
    rules = checked[1]
    fs = _many(30).findings()
    assert junit_xml(rules, fs) == _junit_reference(rules, fs)
    assert junit_xml(rules, []) == _junit_reference(rules, [])
    assert junit_xml([], FindingColumns()) == _junit_reference([], [])


def _junit_peak(rules, found: FindingColumns, dest) -> int:
    found.messages()
    staged = Staged(dest)
    tracemalloc.start()
    try:
        staged.write_text(junit_xml_parts(rules, found))
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    staged.commit()
    return peak


def test_junit_writing_holds_a_chunk_not_the_text(checked, tmp_path, monkeypatch):
    """Four times the findings: the peak while writing grows by a small part of what the
    text grows (each row's testcase number, a few numpy integers per finding); building
    every Finding and the whole text grew it by more than the text."""
    monkeypatch.setattr("cananalyze.outputs.junit.CHUNK", 500)
    rules = checked[1]
    small = _junit_peak(rules, _many(5_000), tmp_path / "small.xml")
    big = _junit_peak(rules, _many(20_000), tmp_path / "big.xml")
    grown = (tmp_path / "big.xml").stat().st_size - (tmp_path / "small.xml").stat().st_size
    assert big - small < grown / 3, (small, big, grown)
