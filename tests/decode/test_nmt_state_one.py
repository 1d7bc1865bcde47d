"""Issue 44 item 5 / issue 36: a node's NMT state over time is one computation
(`decode/nmt_state.NmtStates`): `--summary`, the checks, the event log, the nodes
table's `last_state` and the report say the same. ZeroErr's log2 (a log without
times) has a boot-up, then NMT start / pre-operational / start / stop commands and no
heartbeat: the node ends stopped, where the nodes table used to say `bootup`."""

from __future__ import annotations

import re
import subprocess
import sys

import pyarrow.parquet as pq
from conftest import real_file

import cananalyze

LOG2 = "SeonilChoi__CANOPEN-SDK/log2.txt"
STORY = ["pre-operational", "operational", "pre-operational", "operational", "stopped"]


def _cli(*args: str) -> str:
    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, check=False
    )
    assert done.returncode in (0, 1), done.stderr
    return done.stdout


def test_one_nmt_story_in_every_output(tmp_path):
    log = real_file(LOG2)
    summary = _cli("decode", str(log), "--summary")
    line = next(x for x in summary.splitlines() if x.startswith("NMT state node 11:"))
    steps = re.findall(r"(?:line (\d+)|\+[\d.]+ s) ([a-z-]+) \((\w+)\)", line)
    assert [s for _, s, _ in steps] == STORY
    cap = cananalyze.load(log)
    ev = cap.events[cap.events.kind == "nmt_state"]
    assert [m.split("NMT state ")[1] for m in ev.message] == STORY
    # each change at the frame that made it: the boot-up, then the NMT commands
    lines = open(log).read().splitlines()
    assert [lines[r].split()[1] for r in ev.row] == ["70B", "000", "000", "000", "000"]
    assert cap.nodes.loc[11, "last_state"] == "stopped"
    _cli("export", str(log), "--parquet", str(tmp_path / "pq"), "-q")
    nodes = pq.read_table(tmp_path / "pq" / "nodes.parquet").to_pylist()
    assert [(r["node"], r["last_state"]) for r in nodes] == [(11, "stopped")]
    _cli("report", str(log), "-o", str(tmp_path / "r.html"))
    assert "last NMT state stopped" in (tmp_path / "r.html").read_text()


def test_a_log_without_times_has_no_durations_and_tells_states_by_line():
    """Issue 44 item 2: `--summary` on a log without times printed 'duration: 0.000000
    s', SDO latencies of 0.00 ms and NMT states at '+3.000 s' (the line number read as
    a time); now it says once that times are not known and gives the lines."""
    log = real_file(LOG2)
    summary = _cli("decode", str(log), "--summary")
    assert "duration: not known (the log has no timestamps)" in summary
    assert "periods, gaps and latencies: not known (the log has no timestamps)" in summary
    assert "latency" not in summary.replace("gaps and latencies", "")
    assert " 0.00" not in summary and "+3.000 s" not in summary
    line = next(x for x in summary.splitlines() if x.startswith("NMT state node 11:"))
    lines = open(log).read().splitlines()
    at = [int(n) for n in re.findall(r"line (\d+)", line)]
    assert at == [3, 18, 29, 60, 1239]
    assert lines[2].split()[1] == "70B" and all(lines[n - 1].split()[1] == "000" for n in at[1:])
    timed = _cli(
        "decode", str(real_file("hilch__canopen-message-interpreter/pcan3.trc")), "--summary"
    )
    assert "not known" not in timed and "SDO latency per node:" in timed
