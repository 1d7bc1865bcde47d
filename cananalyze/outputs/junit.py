"""JUnit XML: one testcase per rule and node (or COB-ID), failures carrying the findings.

Written with the standard library's ElementTree (the format is five elements);
junitparser reads it back in the tests.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from ..checks.columns import FindingColumns
from ..checks.finding import TABLE_COLUMNS, Finding, show
from ..checks.rule import Rule


def _subject(rule: Rule, s, bus: str | None = None) -> str:
    name = rule.name if bus is None else f"{rule.name} {bus}"  # several buses: which one
    if s is None:
        return name
    if rule.name in ("assert_pdo_rate", "unknown_cob_id"):
        return f"{name} 0x{s:03X}"
    return f"{name} node {s}"


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
        cases.setdefault(_subject(rule, key, f.bus) if rule else f.rule, []).append(f)
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
    return _line(
        f.t, f.t_rel, f.line, f.node, f.cob_id, f.severity, f.rule, f.message, f.measured,
        f.expected, f.basis, f.why, f.bus,
    )  # fmt: skip


def format_rows(found: FindingColumns, idx) -> list[str]:
    """`format_finding` of rows `idx` of the columns, without a Finding per row (the
    terminal prints thousands of end-of-log results on a long log)."""
    sub = found.take(np.asarray(idx, np.int64))
    cols = {c: sub.column(c) for c in TABLE_COLUMNS if c != "t_rel"}
    # the time as Finding holds it (the record's is rounded to the microsecond)
    cols["t_rel"] = [None if v != v else v for v in sub.t_rel.tolist()]
    for i in np.flatnonzero(np.not_equal(sub.obj, None)).tolist():
        cols["t_rel"][i] = sub.obj[i].t_rel
    cols["bus"] = sub.column("bus")
    return [
        _line(*r)
        for r in zip(
            *(cols[c] for c in ("t", "t_rel", "line", "node", "cob_id", "severity", "rule")),
            *(cols[c] for c in ("message", "measured", "expected", "basis", "why", "bus")),
            strict=True,
        )
    ]


def _line(
    t, t_rel, line, node, cob_id, severity, rule, message, measured, expected, basis, why, bus=None
):
    who = "-" if node is None else str(node)
    where = "node" if bus is None else f"{bus} node"  # several buses: "can1 node 5"
    cob = "" if cob_id is None else f" 0x{cob_id:03X}"
    if line is not None:
        when = f"line {line}"
    else:
        when = f"{t_rel:+.3f} s" if t_rel is not None else f"{t:.6f}"
    basis = f"; {basis}" if basis else ""
    return (
        f"{when} {where} {who}{cob} [{severity}] {rule}: {message} "
        f"(measured {show(measured)}, expected {show(expected)}{basis}). {why}"
    )
