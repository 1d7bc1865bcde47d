"""JUnit XML: one testcase per rule and node (or COB-ID), failures carrying the findings.

Written with the standard library's ElementTree (the format is five elements);
junitparser reads it back in the tests.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

from ..checks.columns import FindingColumns
from ..checks.finding import Finding, show
from ..checks.rule import Rule
from .atomic import write_text_atomic


def _subject(rule: Rule, s) -> str:
    if s is None:
        return rule.name
    if rule.name in ("assert_pdo_rate", "unknown_cob_id"):
        return f"{rule.name} 0x{s:03X}"
    return f"{rule.name} node {s}"


def junit_xml(
    rules: list[Rule],
    findings: list[Finding],
    name: str = "cananalyze check",
    properties: dict[str, str] | None = None,
) -> str:
    """The report; `properties` (e.g. the HTML report's path) go in the suite's <properties>."""
    cases: dict[str, list[Finding]] = {}
    for rule in rules:
        subjects = rule.subjects or {None}
        for s in sorted(subjects, key=lambda x: (x is not None, x or 0)):
            cases.setdefault(_subject(rule, s), [])
    by_rule = {r.name: r for r in rules}
    for f in findings:
        rule = by_rule.get(f.rule)
        key = f.cob_id if rule and rule.name in ("assert_pdo_rate", "unknown_cob_id") else f.node
        cases.setdefault(_subject(rule, key) if rule else f.rule, []).append(f)
    failing = sum(1 for fs in cases.values() if any(f.fails for f in fs))
    suite = ET.Element(
        "testsuite", name=name, tests=str(len(cases)), failures=str(failing), errors="0"
    )
    if properties:
        props = ET.SubElement(suite, "properties")
        for key, value in properties.items():
            ET.SubElement(props, "property", name=key, value=value)
    for case, fs in cases.items():
        tc = ET.SubElement(suite, "testcase", classname=f"cananalyze.{case.split()[0]}", name=case)
        bad = [f for f in fs if f.fails]
        if bad:
            fail = ET.SubElement(
                tc,
                "failure",
                message=f"{len(bad)} finding(s): {bad[0].message}",
                type=bad[0].severity,
            )
            fail.text = "\n".join(format_finding(f) for f in bad)
        info = [f for f in fs if not f.fails]
        if info:
            ET.SubElement(tc, "system-out").text = "\n".join(format_finding(f) for f in info)
    root = ET.Element("testsuites")
    root.append(suite)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


def format_finding(f: Finding) -> str:
    """One line per finding, time from the start of the log (absolute `t` stays in JSON)."""
    node = "-" if f.node is None else str(f.node)
    cob = "" if f.cob_id is None else f" 0x{f.cob_id:03X}"
    if f.line is not None:
        when = f"line {f.line}"
    else:
        when = f"{f.t_rel:+.3f} s" if f.t_rel is not None else f"{f.t:.6f}"
    basis = f"; {f.basis}" if f.basis else ""
    return (
        f"{when} node {node}{cob} [{f.severity}] {f.rule}: {f.message} "
        f"(measured {show(f.measured)}, expected {show(f.expected)}{basis}). {f.why}"
    )


def write_junit(
    path: str | Path,
    rules: list[Rule],
    findings: list[Finding],
    properties: dict[str, str] | None = None,
) -> None:
    write_text_atomic(path, junit_xml(rules, findings, properties=properties))


def write_findings_json(path: str | Path, findings: list[Finding] | FindingColumns) -> None:
    if isinstance(findings, FindingColumns):
        records = findings.records()  # from the columns, no Finding objects
    else:
        records = [f.record() for f in findings]
    write_text_atomic(path, json.dumps(records, indent=1) + "\n")
