"""Every door goes through one pipeline, so the outputs agree: export's findings are check's,
the nodes table names the devices, the assertions decode like load(), and the library
never imports the command line."""

from __future__ import annotations

import ast
import json
import os
import pty
import select
import socket
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from conftest import ROOT, SAMPLES, generated_log

import cananalyze
from cananalyze.api import assertions

FAULTS = SAMPLES / "faults.log"
NETWORK = SAMPLES / "network.toml"
RULES = SAMPLES / "rules.yaml"


def cli(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, **(env or {})},
    )


def _finding_rows(records: list[dict]) -> list[tuple]:
    keys = ("t", "rule", "severity", "node", "cob_id", "message", "measured", "expected")
    keys += ("basis", "line")  # where the expectation came from, and a line when untimed
    out = []
    for r in records:
        row = []
        for k in keys:
            v = r[k]
            if isinstance(v, float) and v != v:  # pandas NaN for a missing value
                v = None
            if k in ("measured", "expected") and v is not None:
                v = str(v)  # one Parquet column holds numbers and texts: as text
            row.append(v)
        out.append(tuple(row))
    return out


@pytest.mark.parametrize("rules", [False, True])
def test_export_findings_table_equals_check_json(tmp_path, rules):
    """On main before the redesign, findings.parquet had 0 rows where check found 12 (16)."""
    extra = ["--rules", RULES] if rules else []
    r = cli("check", FAULTS, "--network", NETWORK, *extra, "--json", tmp_path / "f.json")
    assert r.returncode == 1, r.stderr
    expected = json.loads((tmp_path / "f.json").read_text())
    assert len(expected) == (16 if rules else 12)
    r = cli("export", FAULTS, "--network", NETWORK, *extra, "--parquet", tmp_path / "pq", "-q")
    assert r.returncode == 0, r.stderr
    table = pq.read_table(tmp_path / "pq" / "findings.parquet").to_pylist()
    assert _finding_rows(table) == _finding_rows(expected)
    cap = cananalyze.load(FAULTS, network=NETWORK, rules=RULES if rules else None)
    assert _finding_rows(cap.findings.to_dict("records")) == _finding_rows(expected)


def test_nodes_table_names_the_devices_of_the_network_file(tmp_path):
    r = cli("export", FAULTS, "--network", NETWORK, "--parquet", tmp_path, "-q")
    assert r.returncode == 0, r.stderr
    nodes = pq.read_table(tmp_path / "nodes.parquet").to_pandas()
    assert nodes["profile"].to_dict() == {3: "mcb560", 5: "dat7014", 6: "dat7130", 7: "i7231d"}
    assert set(nodes["identified_by"]) == {"network file"}
    cap = cananalyze.load(FAULTS, network=NETWORK)
    assert cap.nodes["profile"].to_dict() == nodes["profile"].to_dict()


def test_nodes_identified_from_the_log_say_how(tmp_path):
    """commissioning.log reads each node's identity by SDO: the nodes table says so."""
    r = cli("export", SAMPLES / "commissioning.log", "--parquet", tmp_path, "-q")
    assert r.returncode == 0, r.stderr
    nodes = pq.read_table(tmp_path / "nodes.parquet").to_pandas()
    assert nodes.loc[5, "profile"] == "dat7014"
    assert "0x1018" in nodes.loc[5, "identified_by"]


def test_assertions_on_a_path_decode_like_load():
    """ch3 of node 5 comes from the network file's profile: the module's assertion saw no
    signal at all before ("never seen"), while load()'s found the out-of-range value."""
    with pytest.raises(AssertionError) as via_load:
        cananalyze.load(FAULTS, network=NETWORK).assert_signal_range(5, "ch3", -50, 150)
    with pytest.raises(AssertionError) as via_path:
        assertions.assert_signal_range(FAULTS, 5, "ch3", -50, 150, network=NETWORK)
    for exc in (via_load, via_path):
        assert "never seen" not in str(exc.value)
        assert "3276.7" in str(exc.value)
    assertions.assert_signal_range(FAULTS, 5, "ch1", -50, 150, network=NETWORK)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_connect_to_no_viewer_is_one_line_and_exit_2():
    port = _free_port()
    r = cli("decode", SAMPLES / "demo.log", "--connect", f"127.0.0.1:{port}")
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"127.0.0.1:{port}" in lines[0], r.stderr
    assert "Traceback" not in r.stderr


def test_library_never_imports_the_cli():
    package = ROOT / "cananalyze"
    offenders = []
    for path in package.rglob("*.py"):
        rel = path.relative_to(package)
        if rel.parts[0] == "cli" or rel.name == "__main__.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                target = ("." * node.level) + (node.module or "")
                names = [a.name for a in node.names]
                if "cli" in target.split(".") or (target.strip(".") == "" and "cli" in names):
                    offenders.append(f"{rel}: from {target} import {', '.join(names)}")
            elif isinstance(node, ast.Import):
                offenders += [f"{rel}: {a.name}" for a in node.names if ".cli" in a.name]
    assert not offenders


def test_sdo_lines_carry_their_times():
    out = cli("decode", SAMPLES / "demo.log", "--sdo").stdout.splitlines()
    assert out and all(line.split()[0].replace(".", "").isdigit() for line in out)
    assert out[0].startswith("    0.020700  node 5 SDO read 0x1018:01")


def test_signal_lines_count_from_the_first_frame_like_frame_lines():
    rel = cli("decode", SAMPLES / "demo.log", "--signals", "--device", "5=dat7014").stdout
    first = rel.splitlines()[0]
    assert first.split()[0] == "0.100400"  # not 1767225600.100400
    frames = cli("decode", SAMPLES / "demo.log", "--node", "5", "--service", "tpdo").stdout
    assert frames.split()[0] == "0.100400"
    absolute = cli(
        "decode", SAMPLES / "demo.log", "--signals", "--device", "5=dat7014", "--time", "abs"
    )
    assert absolute.stdout.split()[0] == "1767225600.100400"
    abs_frames = cli("decode", SAMPLES / "demo.log", "--time", "abs").stdout
    assert abs_frames.split()[0] == "1767225600.000000"


def test_summary_as_jsonl_is_one_json_record():
    r = cli("decode", SAMPLES / "demo.log", "--summary", "--format", "jsonl", "--bitrate", "250000")
    lines = r.stdout.splitlines()
    assert len(lines) == 1
    rec = json.loads(lines[0])
    assert rec["kind"] == "summary" and rec["frames"] == 185
    assert rec["frames_per_service"]["sync"] == 20
    assert 0 < rec["bus_load_percent"] < 100
    assert {d["node"] for d in rec["devices"]} == {3, 5, 10}


def test_a_filter_that_matches_nothing_says_so():
    r = cli("decode", SAMPLES / "demo.log", "--node", "99")
    assert r.returncode == 0 and r.stdout == ""
    assert "--node 99 matched none of the 185 frames" in r.stderr
    assert "nodes 3, 5, 10" in r.stderr
    r = cli("check", FAULTS, "--from", "1000")
    assert "--from 1000 matched none" in r.stderr
    assert r.returncode == 0  # nothing shown, nothing violated


def test_filters_choose_what_every_output_shows(tmp_path):
    r = cli("export", FAULTS, "--network", NETWORK, "--node", "5", "--parquet", tmp_path, "-q")
    assert r.returncode == 0, r.stderr
    frames = pq.read_table(tmp_path / "frames.parquet").to_pandas()
    assert set(frames["node"].dropna()) == {5}
    findings = pq.read_table(tmp_path / "findings.parquet").to_pandas()
    assert len(findings) and set(findings["node"]) == {5}
    signals = pq.read_table(tmp_path / "signals.parquet").to_pandas()
    assert set(signals["node"]) == {5}


def test_repr_of_a_loaded_log_is_short():
    cap = cananalyze.load(SAMPLES / "commissioning.log")
    text = repr(cap)
    assert len(text) < 300 and "\n" not in text
    assert "1,200 frames" in text and "nodes 3, 5, 6, 7" in text


def _on_a_terminal(args: list, env: dict | None = None, stream: str = "stdout") -> bytes:
    """Run the CLI with stdout (or stderr) on a pseudo-terminal; what it wrote there."""
    master, slave = pty.openpty()
    kwargs = {stream: slave}
    other = "stderr" if stream == "stdout" else "stdout"
    kwargs[other] = subprocess.DEVNULL
    proc = subprocess.Popen(
        [sys.executable, "-m", "cananalyze", *map(str, args)],
        cwd=ROOT,
        env={**os.environ, "COLUMNS": "120", **(env or {})},
        **kwargs,
    )
    os.close(slave)
    out = b""
    while True:
        ready, _, _ = select.select([master], [], [], 30)
        if not ready:
            break
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the child closed its end
            break
        if not chunk:
            break
        out += chunk
    proc.wait(timeout=60)
    os.close(master)
    return out


def test_check_is_coloured_on_a_terminal_unless_no_color():
    coloured = _on_a_terminal(["check", FAULTS, "--network", NETWORK])
    assert b"\x1b[" in coloured and b"[error]" in coloured
    plain = _on_a_terminal(["check", FAULTS, "--network", NETWORK], env={"NO_COLOR": "1"})
    assert b"\x1b[" not in plain and b"[error]" in plain
    assert b"\x1b[" not in cli("check", FAULTS, "--network", NETWORK).stdout.encode()
    decoded = _on_a_terminal(["decode", SAMPLES / "demo.log"], env={"NO_COLOR": "1"})
    assert b"\x1b[" not in decoded and b"boot-up" in decoded


@pytest.mark.slow
def test_progress_bar_on_a_terminal(tmp_path):
    log = generated_log(tmp_path, 300_000)
    now = {"CANANALYZE_PROGRESS_DELAY": "0"}  # the bar from the start, however fast the run
    shown = _on_a_terminal(["export", log, "--parquet", tmp_path / "pq"], env=now, stream="stderr")
    assert b"%" in shown and b"frames" in shown
    quiet = _on_a_terminal(
        ["export", log, "--parquet", tmp_path / "pq2", "-q"], env=now, stream="stderr"
    )
    assert b"%" not in quiet


def test_sinks_are_aborted_when_one_fails(tmp_path):
    """An export whose second output cannot be written leaves no first output either."""
    out = tmp_path / "pq"
    r = cli("export", FAULTS, "--parquet", out, "--mcap", tmp_path / "missing" / "x.mcap")
    assert r.returncode == 2 and "does not exist" in r.stderr
    assert not out.exists() or not list(Path(out).iterdir())


def test_check_api_gives_the_findings_of_the_check_command(tmp_path):
    found = cananalyze.check(FAULTS, network=NETWORK, rules=RULES)
    r = cli("check", FAULTS, "--network", NETWORK, "--rules", RULES, "--json", tmp_path / "f.json")
    assert r.returncode == 1, r.stderr
    assert [f.record() for f in found] == json.loads((tmp_path / "f.json").read_text())
    assert sum(f.fails for f in found) == 16
    assert cananalyze.check(SAMPLES / "commissioning.log", rules=RULES) == []
    assert cananalyze.Options is cananalyze.pipeline.Options


def test_sdo_records_name_their_cob_ids_and_frames_their_interface():
    """The sdo record's `channel` held a COB-ID pair where frame records hold the interface."""
    lines = [
        json.loads(x)
        for x in cli("decode", SAMPLES / "demo.log", "--format", "jsonl").stdout.splitlines()
    ]
    frames = [r for r in lines if r["kind"] == "frame"]
    sdo = [r for r in lines if r["kind"] == "sdo"]
    assert frames and {r["channel"] for r in frames} == {"can0"}
    assert sdo and all("channel" not in r for r in sdo)
    assert {tuple(r["cob_ids"]) for r in sdo if r["node"] == 5} == {(0x605, 0x585)}
