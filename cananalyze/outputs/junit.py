"""JUnit XML: one testcase per rule and node (or COB-ID), failures carrying the findings.

Written with the standard library's ElementTree (the format is five elements), the
findings' lines streamed into it a chunk at a time; junitparser reads it back in the tests.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence
from xml.sax.saxutils import escape

import numpy as np

from cananalyze.checks.rule import Rule
from cananalyze.core.columns.order import first_seen_codes
from cananalyze.core.finding import TABLE_COLUMNS, Finding, show
from cananalyze.core.finding_columns import FindingColumns

CHUNK = 4096  # findings' lines formatted at a time
_BY_COB_ID = ("assert_pdo_rate", "unknown_cob_id")  # rules whose testcases are per COB-ID


def _subject(rule: Rule, s, bus: str | None = None) -> str:
    name = rule.name if bus is None else f"{rule.name} {bus}"  # several buses: which one
    if s is None:
        return name
    if rule.name in _BY_COB_ID:
        return f"{name} 0x{s:03X}"
    return f"{name} node {s}"


def junit_xml(
    rules: list[Rule],
    findings: Sequence[Finding] | FindingColumns,
    name: str = "cananalyze check",
) -> str:
    """The report (the whole text of `junit_xml_parts`)."""
    return "".join(junit_xml_parts(rules, findings, name))


def junit_xml_parts(
    rules: list[Rule],
    findings: Sequence[Finding] | FindingColumns,
    name: str = "cananalyze check",
    properties: dict[str, str] | None = None,
) -> Iterator[str]:
    """`junit_xml`'s text in pieces: the findings' lines a chunk at a time.

    The elements (one testcase per rule and node) are few and built with ElementTree as
    they always were; each failure's and system-out's text, which holds every finding's
    line, is a row-number placeholder there, and is written in its place from the
    columns, escaped as ElementTree escapes text. A faulty bus's hundreds of thousands
    of findings never become Finding objects nor one string."""
    found = findings if isinstance(findings, FindingColumns) else FindingColumns.of(findings)
    cases, rows = _cases(rules, found)
    fails = found.fails
    texts: list[np.ndarray] = []  # each placeholder's rows
    failing = sum(1 for idx in rows if fails[idx].any())
    suite = ET.Element(
        "testsuite", name=name, tests=str(len(cases)), failures=str(failing), errors="0"
    )
    if properties:
        props = ET.SubElement(suite, "properties")
        for key, value in properties.items():
            ET.SubElement(props, "property", name=key, value=value)
    for case, idx in zip(cases, rows, strict=True):
        tc = ET.SubElement(suite, "testcase", classname=f"cananalyze.{case.split()[0]}", name=case)
        bad = idx[fails[idx]]
        if bad.size:
            first = found.finding(int(bad[0]))
            fail = ET.SubElement(
                tc,
                "failure",
                message=f"{bad.size} finding(s): {first.message}",
                type=first.severity,
            )
            fail.text = str(len(texts))
            texts.append(bad)
        info = idx[~fails[idx]]
        if info.size:
            ET.SubElement(tc, "system-out").text = str(len(texts))
            texts.append(info)
    root = ET.Element("testsuites")
    root.append(suite)
    ET.indent(root)
    skeleton = ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"
    # ">N</" is only ever a placeholder: the other texts are indentation, and attribute
    # values have their ">" escaped
    pieces = re.split(r">(\d+)</", skeleton)
    yield pieces[0]
    for k in range(1, len(pieces), 2):
        yield ">"
        idx = texts[int(pieces[k])]
        for start in range(0, idx.size, CHUNK):
            lines = "\n".join(format_rows(found, idx[start : start + CHUNK]))
            yield ("\n" if start else "") + escape(lines)  # as ElementTree escapes text
        yield "</" + pieces[k + 1]


def _cases(rules: list[Rule], found: FindingColumns) -> tuple[list[str], list[np.ndarray]]:
    """The testcases (each rule's subjects, then as findings first name them) and the
    rows of each, in row order; counted on columns, one name per (rule, node, bus)."""
    names: dict[str, int] = {}
    for rule in rules:
        subjects = rule.subjects or {None}
        for s in sorted(subjects, key=lambda x: (x is not None, x or 0)):
            names.setdefault(_subject(rule, s), len(names))
    case = np.zeros(len(found), np.int64)
    if len(found):
        by_rule = {r.name: r for r in rules}
        rule_code, rule_names = first_seen_codes(found.column("rule"))
        by_cob = np.array([r in by_rule and r in _BY_COB_ID for r in rule_names])
        key = np.where(by_cob[rule_code], found.ints("cob_id")[0], found.ints("node")[0])
        bus_code, buses = first_seen_codes(found.column("bus"))
        combo = ((rule_code << 31) | (key + 1)) * len(buses) + bus_code  # key: 29 bits
        del rule_code, key, bus_code
        _, first, inverse = np.unique(combo, return_index=True, return_inverse=True)
        del combo
        case_of = np.empty(first.size, np.int64)
        for u in np.argsort(first, kind="stable").tolist():  # as the findings name them
            f = found.finding(int(first[u]))  # one per (rule, node, bus)
            rule = by_rule.get(f.rule)
            key = f.cob_id if rule and rule.name in _BY_COB_ID else f.node
            name = _subject(rule, key, f.bus) if rule else f.rule
            case_of[u] = names.setdefault(name, len(names))
        case = case_of[inverse.reshape(-1)]
    order = np.argsort(case, kind="stable")
    bounds = np.searchsorted(case[order], np.arange(len(names) + 1))
    rows = [order[bounds[c] : bounds[c + 1]] for c in range(len(names))]
    return list(names), rows


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
