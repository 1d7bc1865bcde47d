"""A rules file of many assertions (issue 38, item 5: bounded on legal input).

A 2 MB file of 50,000 heartbeat assertions is under the 4 MiB limit: it is parsed once
per run, by PyYAML's C safe loader where there is one, and judged per node present in
a batch, identical assertions compared once. These tests hold the findings to what the
assertions say one by one; the time it takes is measured by benchmarks/bench_bounded.py,
never here."""

from __future__ import annotations

import json
import random
from collections import Counter

import pytest
import yaml
from conftest import SAMPLES, generated_log

from cananalyze.checks.rules.assert_heartbeat import AssertHeartbeat
from cananalyze.checks.rules.assert_signal import AssertSignal
from cananalyze.cli.main import main
from cananalyze.config import filelines
from cananalyze.core.errors import InputError
from cananalyze.formats.source import open_log
from cananalyze.pipeline import Options, build_checker, build_decoder

DEMO = SAMPLES / "demo.log"


def _distinct(n: int = 200) -> list[str]:
    """n different heartbeat assertions: every node 1..127, the demo's nodes (3, 5, 6,
    10) with periods they keep and break, tolerances and severities of their own."""
    out = []
    periods, tols = (100, 50, 200, 1000, 10), (None, 0.1, 0.2, 0.05, 0.5)
    k = 0
    while len(out) < n:
        node = (3, 5, 6, 10)[k % 4] if k % 3 == 0 else k % 127 + 1
        extra = "" if tols[k % 5] is None else f", tolerance: {tols[k % 5]}"
        extra += ", severity: warning" if k % 7 == 0 else ""
        item = f"heartbeat: {{node: {node}, period_ms: {periods[k // 5 % 5]}{extra}}}"
        if item not in out:
            out.append(item)
        k += 1
    return out


def _rules(path, items: list[str]):
    path.write_text("tolerance: 0.1\nassert:\n" + "".join(f"  - {i}\n" for i in items))
    return path


def _check_json(tmp_path, rules, log=DEMO, name="out.json") -> list[dict]:
    out = tmp_path / name
    assert main(["check", str(log), "--rules", str(rules), "--json", str(out), "-q"]) in (0, 1)
    return json.loads(out.read_text())


def _counted(monkeypatch) -> Counter:
    """Calls of the one YAML parse (`_load_yaml`) and of the file reader, per file."""
    calls: Counter = Counter()
    parse, read_tree = filelines._load_yaml, filelines.read_tree

    def counting_parse(text, loader, path):
        calls["yaml"] += 1
        return parse(text, loader, path)

    def counting_read(path, what):
        calls[what] += 1
        return read_tree(path, what)

    monkeypatch.setattr(filelines, "_load_yaml", counting_parse)
    monkeypatch.setattr("cananalyze.checks.rulesfile.read_tree", counting_read)
    monkeypatch.setattr("cananalyze.config.netfile.read_tree", counting_read)
    return calls


def test_check_parses_the_rules_file_once(tmp_path, monkeypatch):
    """`check --rules` with a network: section (read by the checks and by the decoder's
    declarations alike), one bus and two (another bus's checker is a copy): one parse."""
    rules = tmp_path / "r.yaml"
    rules.write_text(
        "assert:\n  - heartbeat: {node: 5, period_ms: 100}\n"
        "network:\n  nodes:\n    5: {device: dat7014, heartbeat_ms: 100}\n"
    )
    two = tmp_path / "two.log"
    lines = DEMO.read_text().splitlines()
    both = sorted(lines + [x.replace(" can0 ", " can1 ") for x in lines])  # by time
    two.write_text("\n".join(both) + "\n")
    for log in (DEMO, two):
        calls = _counted(monkeypatch)
        found = _check_json(tmp_path, rules, log)
        assert calls == {"rules file": 1, "yaml": 1}, (log, calls)
    buses = {f.get("bus") for f in found}
    assert buses >= {"can0", "can1"}  # the two-bus run judged both


def test_api_and_network_file_parse_each_file_once(tmp_path, monkeypatch):
    from cananalyze import load

    rules = _rules(tmp_path / "r.yaml", _distinct(20))
    network = tmp_path / "net.yaml"
    network.write_text("nodes:\n  5: {device: dat7014}\n")
    calls = _counted(monkeypatch)
    cap = load(str(DEMO), rules=str(rules), network=str(network))
    assert len(cap.findings) > 0
    assert calls == {"rules file": 1, "network file": 1, "yaml": 2}


def test_the_c_loader_and_the_python_loader_read_the_same(tmp_path, monkeypatch):
    """The C loader where PyYAML has it (never the full loader), the pure-Python safe one
    otherwise: the same data and the same lines, anchors, merge keys and tags included."""
    if yaml.__with_libyaml__:
        assert filelines.yaml_loader() is yaml.CSafeLoader
    text = (
        "base: &b {heartbeat_ms: 100, name: 'x'}\n"
        "nodes:\n  5:\n    <<: *b\n    name: drive\n  0x06: {heartbeat_ms: 0x64}\n"
        "known_cob_ids: [0x10A, 266, !!int '7']\nbitrate: 500_000\n"
        "when: 2024-01-02\nlist:\n  - [1, 2.5, .inf, ~, yes, 'no']\n"
    )
    p = tmp_path / "n.yaml"
    p.write_text(text)
    fast, fast_lines = filelines.read_tree(p, "network file")
    monkeypatch.setattr(filelines, "yaml_loader", lambda: yaml.SafeLoader)
    slow, slow_lines = filelines.read_tree(p, "network file")
    assert fast == slow == yaml.load(text, Loader=yaml.SafeLoader)
    assert fast_lines.map == slow_lines.map
    assert fast_lines.line(("nodes", "6", "heartbeat_ms")) == 6
    assert fast_lines.line(("nodes", "5", "<<", "heartbeat_ms")) == 1  # the anchor's line
    assert fast_lines.line(("nodes", "5", "heartbeat_ms")) == 3  # merged: the node's line
    bad = tmp_path / "bad.yaml"
    bad.write_text("x: !!python/object:os.system ls\n")
    with pytest.raises(InputError, match=r"bad\.yaml:1: not valid YAML"):
        filelines.read_tree(bad, "rules file")


def _scaled(tmp_path, copies: int) -> tuple[list[dict], list[dict]]:
    """(findings of the 200 distinct assertions, findings of the same 200 written
    `copies` times over: first in the same order, then shuffled)."""
    one = _distinct(200)
    rest = one * (copies - 1)
    random.Random(5).shuffle(rest)
    few = _check_json(tmp_path, _rules(tmp_path / "few.yaml", one), name="few.json")
    many = _check_json(tmp_path, _rules(tmp_path / "many.yaml", one + rest), name="many.json")
    return few, many


def _same_as_copies(few: list[dict], many: list[dict], copies: int) -> None:
    """Every finding of an assertion `copies` times, the other rules' once, in time order."""
    key = lambda f: json.dumps(f, sort_keys=True)  # noqa: E731
    asserted = Counter(key(f) for f in few if f["rule"] == "assert_heartbeat")
    others = [key(f) for f in few if f["rule"] != "assert_heartbeat"]
    assert asserted and others
    want = Counter(others) + Counter({k: n * copies for k, n in asserted.items()})
    assert Counter(key(f) for f in many) == want
    assert [key(f) for f in many if f["rule"] != "assert_heartbeat"] == others
    times = [f["t"] for f in many]
    assert times == sorted(times)


def test_5000_assertions_find_what_their_200_distinct_ones_find(tmp_path):
    few, many = _scaled(tmp_path, 25)
    _same_as_copies(few, many, 25)


@pytest.mark.slow
def test_50000_assertions_find_what_their_200_distinct_ones_find(tmp_path):
    """2.7 MB of rules (under the 4 MiB limit): the same findings, 250 times each."""
    few, many = _scaled(tmp_path, 250)
    assert (tmp_path / "many.yaml").stat().st_size > 2_000_000
    _same_as_copies(few, many, 250)


def _run(rules_file, log, batch: int, monkeypatch=None, one_by_one: bool = False):
    """Every finding of `rules_file` on `log` fed in batches of `batch` frames;
    `one_by_one`: every assertion judged by its own `process` (no `together`)."""
    if one_by_one:
        monkeypatch.setattr(AssertHeartbeat, "together", None)
        monkeypatch.setattr(AssertSignal, "together", None)
    opts = Options(rules=rules_file)
    checker = build_checker(opts)
    decoder = build_decoder(opts, checker)
    for big in open_log(log).batches():
        for i in range(0, len(big), batch):
            decoder.decode(big.take(slice(i, i + batch)))
    decoder.finish()
    if one_by_one:
        monkeypatch.undo()
    return [f.record() for f in checker.findings]


@pytest.mark.parametrize("batch", [37, 5000])
def test_assertions_judged_together_as_each_alone(tmp_path, monkeypatch, batch):
    """The same findings, in the same order, whether the assertions are judged together
    (indexed by node, identical ones compared once) or each by its own `process`: on a
    faulty 16-node log in small and large batches, with heartbeat and signal assertions,
    repeated, some of a node no frame comes from."""
    log = generated_log(tmp_path, 6000)
    items = _distinct(60) + [
        f"signal: {{node: {n}, signal: {s}, min: {lo}, max: {hi}}}"
        for n in (1, 2, 5, 9, 20)
        for s, lo, hi in (("ch1", 0, 100), ("ch2", -1000, 1000), ("nope", 0, 1))
    ]
    items = items + items[::3]
    rules = tmp_path / "r.yaml"
    rules.write_text(
        "assert:\n"
        + "".join(f"  - {i}\n" for i in items)
        + "network:\n  nodes:\n"
        + "".join(f"    {n}: {{device: dat7014}}\n" for n in range(1, 17))
    )
    together = _run(rules, log, batch)
    alone = _run(rules, log, batch, monkeypatch, one_by_one=True)
    assert {f["rule"] for f in together} >= {"assert_heartbeat", "assert_signal"}
    assert together == alone
