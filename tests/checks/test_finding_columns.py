"""Findings carried as columns: every output holds the same findings, in the same order,
with the same texts, in both modes; the terminal builds only what it shows.

The generator's log (benchmarks/generate.py) makes findings of every column path: a SYNC
counter that jumps on nearly every SYNC, EMCYs raised and never reset (still active at
the end), heartbeats with no 0x1017 whose learned period is broken by the log's jitter.
Each output is read by an independent reader: json, xml.etree, pyarrow, pandas.
"""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections import Counter

import numpy as np
import pyarrow.parquet as pq
import pytest

from cananalyze.core.finding_columns import FindingColumns
from tests.conftest import ROOT, generated_log

DEVICES = [a for k in range(1, 17) for a in ("--device", f"{k}=dat7014")]


def _cli(args: list[str], pure: bool) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("CANANALYZE_PURE", None)
    if pure:
        env["CANANALYZE_PURE"] = "1"
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )


@pytest.fixture(scope="module")
def outputs(tmp_path_factory) -> dict:
    """check (terminal, --json, --junit) and export --parquet of one log, in both modes."""
    tmp = tmp_path_factory.mktemp("finding_columns")
    log = generated_log(tmp, 60_000)
    out: dict = {"log": log}
    for mode, pure in (("plain", False), ("pure", True)):
        js, xml, pq_dir = tmp / f"{mode}.json", tmp / f"{mode}.xml", tmp / f"{mode}_pq"
        run = _cli(["check", str(log), *DEVICES, "--json", str(js), "--junit", str(xml)], pure)
        assert run.returncode == 1, run.stderr
        exp = _cli(["export", str(log), "--parquet", str(pq_dir), *DEVICES, "-q"], pure)
        assert exp.returncode in (0, 1), exp.stderr
        out[mode] = {
            "stdout": run.stdout,
            "json": json.loads(js.read_text()),
            "junit": ET.parse(xml).getroot(),
            "table": pq.read_table(pq_dir / "findings.parquet").to_pylist(),
        }
    return out


@pytest.mark.slow
def test_every_column_path_is_exercised(outputs) -> None:
    found = outputs["plain"]["json"]
    rules = Counter(f["rule"] for f in found)
    assert rules["sync"] > 1000 and rules["emcy"] > 100 and rules["heartbeat"] > 100
    assert any("still active at the end" in f["message"] for f in found)
    assert any("period learned" in f["message"] for f in found)


def test_same_findings_in_both_modes(outputs) -> None:
    assert outputs["plain"]["json"] == outputs["pure"]["json"]
    assert outputs["plain"]["table"] == outputs["pure"]["table"]
    assert outputs["plain"]["stdout"] == outputs["pure"]["stdout"]
    plain, pure = (ET.tostring(outputs[m]["junit"]) for m in ("plain", "pure"))
    assert plain == pure


def test_table_holds_the_json_findings(outputs) -> None:
    """The findings table (pyarrow) row for row as `check --json`: same order, same texts;
    measured and expected, of mixed types, are text in the table."""
    found, table = outputs["plain"]["json"], outputs["plain"]["table"]
    assert len(table) == len(found)
    for row, f in zip(table, found, strict=True):
        want = {k: v for k, v in f.items() if k != "kind"}
        for k in ("measured", "expected"):
            want[k] = None if want[k] is None else str(want[k])
        assert row == want


def test_junit_lists_every_failing_finding(outputs) -> None:
    """Each failing finding of the JSON is a line of its testcase's failure, in order."""
    found = outputs["plain"]["json"]
    root = outputs["plain"]["junit"]
    lines = []
    for case in root.iter("testcase"):
        fail = case.find("failure")
        if fail is not None:
            lines.extend(fail.text.splitlines())
    failing = [f for f in found if f["severity"] != "info"]
    assert len(lines) == len(failing)
    by_case: dict[tuple, list[str]] = {}
    for f in failing:
        by_case.setdefault((f["rule"], f["node"]), []).append(f["message"])
    for case in root.iter("testcase"):
        fail = case.find("failure")
        if fail is None:
            continue
        m = re.fullmatch(r"(\w+)(?: node (\d+))?", case.get("name"))
        key = (m.group(1), None if m.group(2) is None else int(m.group(2)))
        messages = by_case[key]
        assert len(fail.text.splitlines()) == len(messages)
        for line, msg in zip(fail.text.splitlines(), messages, strict=True):
            assert f"] {key[0]}: {msg} (measured" in line


def test_load_findings_are_the_json_ones(outputs) -> None:
    import cananalyze

    devices = {k: "dat7014" for k in range(1, 17)}
    df = cananalyze.load(str(outputs["log"]), device=devices).findings
    found = outputs["plain"]["json"]
    assert len(df) == len(found)
    assert df["message"].tolist() == [f["message"] for f in found]
    assert df["t"].tolist() == [f["t"] for f in found]
    nodes = df["node"].astype(object).where(df["node"].notna(), None).tolist()
    assert nodes == [f["node"] for f in found]


def test_terminal_caps_the_learned_heartbeat_dropouts(outputs) -> None:
    """Dropouts judged at the end against a learned period are not end-of-log results:
    capped like the others (20 per node), the rest counted; the EMCYs still active at
    the end all show. (Before, every learned dropout was printed as an end result.)"""
    found = outputs["plain"]["json"]
    stdout = outputs["plain"]["stdout"]
    dropouts = Counter(f["node"] for f in found if "period learned" in f["message"])
    assert max(dropouts.values()) > 20
    shown = Counter(
        int(m.group(1))
        for m in re.finditer(r"node (\d+) 0x7.. \[warning\] heartbeat: heartbeat dropout", stdout)
    )
    for node, n in dropouts.items():
        assert shown[node] == min(n, 20)
        if n > 20:
            assert re.search(
                rf"node {node} 0x7.. \[warning\] heartbeat: {n - 20} more like this not shown "
                rf"\({n} in all",
                stdout,
            )
    active = sum("still active at the end" in f["message"] for f in found)
    assert stdout.count("still active at the end of the log") == active


def test_terminal_builds_only_the_texts_it_shows() -> None:
    """A rule's block of 5,000 findings: the terminal asks its text builder for the 20
    it shows and the first hidden one, not for all."""
    from cananalyze.outputs.findings import terminal_cap

    asked: list[int] = []

    def text(idx: np.ndarray) -> list[str]:
        asked.extend(idx.tolist())
        return [f"finding {i}" for i in idx.tolist()]

    block = FindingColumns.block(
        "sync", "error", np.arange(5000, dtype=float), None, 0x80, text, np.arange(5000), 0, ""
    )
    shown, hidden = terminal_cap(block, 20)
    assert shown.tolist() == list(range(20))
    assert sorted(asked) == [20]  # the first hidden one, for its count line
    assert block.messages(shown) == [f"finding {i}" for i in range(20)]
    assert sorted(asked) == list(range(21))
    ((first, n, total),) = hidden.values()
    assert (first.message, n, total) == ("finding 20", 4980, 5000)
    # the JSON records build the rest, once
    recs = block.records()
    assert [r["message"] for r in recs] == [f"finding {i}" for i in range(5000)]
    assert [r["measured"] for r in recs[:3]] == [0, 1, 2]
    assert sorted(asked) == list(range(5000))


def test_findings_sink_output_matches_the_finding_objects() -> None:
    """The columns' records are those of the Finding objects built from them."""
    from cananalyze.outputs.findings import FindingsSink

    block = FindingColumns.block(
        "emcy",
        "warning",
        np.array([2.0, 1.0]),
        3,
        0x83,
        ["b", "a"],
        [0.1 + 0.2, [1.5, 2]],
        "x",
        "w",
    )
    found = FindingColumns.concat(
        [block, FindingColumns.block("sync", "info", [3.0], None, None, ["c"], 1, 1, "")]
    )
    assert [f.record() for f in found] == found.records()
    assert found.records()[0]["measured"] == 0.3  # tidied as Finding does
    sink = FindingsSink(out=io.StringIO())
    sink.write(type("B", (), {"findings": found})())
    assert [f.message for f in sink.failing] == ["a", "b"]  # by time; info does not fail
    assert sink.exit_code == 1


def test_round6_is_pythons_round() -> None:
    """The table's t_rel, rounded as columns, is `round(v, 6)` value for value: random
    times, exact halves of a microsecond and their neighbours, NaN."""
    from cananalyze.core.finding_columns import round6

    rng = np.random.default_rng(7)
    halves = (np.arange(1, 2000) + 0.5) / 1e6
    x = np.concatenate(
        (
            rng.uniform(0, 1e5, 20000),
            rng.uniform(0, 1, 20000),
            halves,
            np.nextafter(halves, 0),
            np.nextafter(halves, 1),
            [0.0, -0.0, 1e-7, 5e-7, 2.5e-6, np.nan],
        )
    )
    want = [None if v != v else round(v, 6) for v in x.tolist()]
    assert round6(x) == want
