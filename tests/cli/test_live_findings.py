"""Live findings as they happen: a node falls silent during `live --check` over slcan on a
pty, and the finding is printed within its period plus tolerance plus half a second,
while the session runs (not at Ctrl-C), once (also in --json and --junit at exit)."""

from __future__ import annotations

import json
import re
import signal
import time

import pytest
from helpers.live_slcan import start_live
from junitparser import JUnitXml

from cananalyze.core.frames import from_rows
from cananalyze.formats.logfile import write_log
from cananalyze.sim.slcan_replay import replay
from tests.cli.test_live_check import _Lines

PERIOD_S = 0.1
JITTER_MS = 150  # slcan frames are time-stamped when the host reads the pty: loaded-machine slack
STOP_S = 2.0  # node 5's last heartbeat; node 6 goes on to END_S
END_S = 5.0


@pytest.mark.slow
def test_silent_node_reported_while_the_session_runs(tmp_path):
    rows = [(0.0, 0x705, b"\x05"), (0.0, 0x706, b"\x05")]
    k = 1
    while k * PERIOD_S <= END_S + 1e-9:
        t = round(k * PERIOD_S, 3)
        if t <= STOP_S:
            rows.append((t, 0x705, b"\x05"))
        rows.append((t, 0x706, b"\x05"))
        k += 1
    log = tmp_path / "silent.log"
    write_log(from_rows(rows), log)
    rules = tmp_path / "rules.yaml"
    rules.write_text(
        f"jitter_ms: {JITTER_MS}\n"
        "network:\n  nodes:\n    5: {heartbeat_ms: 100}\n    6: {heartbeat_ms: 100}\n"
    )
    report, junit = tmp_path / "f.json", tmp_path / "f.xml"
    args = ["--check", str(rules), "--json", str(report), "--junit", str(junit)]
    proc, adapter, _ = start_live(["--plain", *args], cwd=tmp_path)
    out = _Lines(proc.stdout)
    t_start = time.monotonic()
    sent = replay(adapter, str(log), timed=True)
    t_end = time.monotonic()
    time.sleep(0.3)
    assert proc.poll() is None, proc.stderr.read()[-2000:]
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    out.join()
    assert sent == len(rows)
    stopped = [(at, line) for at, line in out.lines if "heartbeat stopped" in line]
    assert stopped, "\n".join(line for _, line in out.lines[-20:])
    at, line = stopped[0]
    assert "node 5" in line or "none since" in line
    bound = PERIOD_S + max(PERIOD_S * 0.1, JITTER_MS / 1000) + 0.5
    # replay paces from its first frame (t = 0 of the log); allow the replay's own start-up
    assert at < t_end, "reported only after the session's traffic ended"
    assert at - (t_start + STOP_S) <= bound + 0.2, (at - t_start, line)
    assert proc.returncode == 1
    found = json.loads(report.read_text())
    hb = [f for f in found if f["rule"] == "heartbeat" and f["node"] == 5]
    assert [f["basis"] for f in hb] == ["0x1017 in the rules file's network:"]  # once
    # node 6 falls silent too, when the replay ends (before Ctrl-C): nothing earlier
    late6 = [f for f in found if f["rule"] == "heartbeat" and f["node"] == 6]
    assert all(f["t_rel"] > END_S for f in late6)
    assert {f["rule"] for f in found} == {"heartbeat"}
    (case,) = [c for s in JUnitXml.fromfile(str(junit)) for c in s if c.name == "heartbeat node 5"]
    assert case.result and "heartbeat stopped" in case.result[0].message


@pytest.mark.slow
def test_only_node_on_the_bus_falls_silent_into_a_file(tmp_path):
    """The only node stops: no frame arrives at all. The finding is on the wall clock,
    within the bound, written into a file (stdout redirected) as it happens; at exit it is
    in --json and --junit once, and in the .rrd streamed during the session."""
    rows = [(round(k * PERIOD_S, 3), 0x705, b"\x05") for k in range(int(STOP_S / PERIOD_S) + 1)]
    log = tmp_path / "alone.log"
    write_log(from_rows(rows), log)
    rules = tmp_path / "rules.yaml"
    rules.write_text(f"jitter_ms: {JITTER_MS}\nnetwork:\n  nodes:\n    5: {{heartbeat_ms: 100}}\n")
    report, junit, rrd, text = (tmp_path / n for n in ("f.json", "f.xml", "live.rrd", "out.txt"))
    args = ["--plain", "--check", str(rules), "--json", str(report), "--junit", str(junit)]
    with open(text, "w") as out:
        proc, adapter, _ = start_live([*args, "--rrd", str(rrd)], cwd=tmp_path, stdout=out)
        sent = replay(adapter, str(log), timed=True)
        t_last = time.monotonic()  # the last heartbeat written to the adapter
        seen = None
        while seen is None and time.monotonic() < t_last + 15:
            lines = text.read_text().splitlines()
            seen = next((x for x in lines if "heartbeat stopped" in x), None)
            at = time.monotonic()
            time.sleep(0.02)
        time.sleep(1.0)  # the .rrd is sent every 0.5 s: read while the session runs
        during = _rrd_events(rrd)
        assert proc.poll() is None, proc.stderr.read()[-2000:]
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
    err = proc.stderr.read()
    assert sent == len(rows) and "Traceback" not in err
    assert any("heartbeat stopped" in r["TextLog:text"][0] for r in during)
    assert seen is not None, text.read_text()[-2000:]
    bound = PERIOD_S + max(PERIOD_S * 0.1, JITTER_MS / 1000) + 0.5
    assert at - t_last <= bound + 0.2, (at - t_last, seen)
    assert "ERROR" in seen and "node 5" in seen
    # the node's last heartbeat was the bus's last frame: the adapter may have stopped
    m = re.search(r"none since (\+[\d.]+ s) .*; no frame from any node since (\+[\d.]+ s) ", seen)
    assert m and m.group(1) == m.group(2), seen
    assert abs(float(m.group(1)[1:-2]) - STOP_S) < 0.2
    assert proc.returncode == 1
    found = json.loads(report.read_text())
    assert [(f["rule"], f["node"]) for f in found] == [("heartbeat", 5)]
    assert found[0]["basis"] == "0x1017 in the rules file's network:"
    # at exit: the same finding, its silence measured until the session ended
    head = seen.split("heartbeat: node 5 ", 1)[1].split(" (", 1)[0]
    assert found[0]["message"].startswith(head + " (")
    assert " ms until the session ended); no frame from any node since " in found[0]["message"]
    (case,) = [c for s in JUnitXml.fromfile(str(junit)) for c in s if c.name == "heartbeat node 5"]
    assert case.result and "no frame from any node since" in case.result[0].message
    # at exit, once, as an error, at the finding's time on the log's clock
    hits = [r for r in _rrd_events(rrd) if "heartbeat stopped" in r["TextLog:text"][0]]
    assert len(hits) == 1 and hits[0]["TextLog:level"][0] == "ERROR"
    assert hits[0]["TextLog:text"][0] == f"[heartbeat] {seen.split('heartbeat: node 5 ', 1)[1]}"
    assert abs(hits[0]["time"].timestamp() - found[0]["t"]) < 1e-3


def _rrd_events(rrd) -> list[dict]:
    """The /events rows of an .rrd, by rerun's own reader (also of one still written)."""
    from rerun.chunk import RrdReader

    return [
        r
        for chunk in RrdReader(rrd).stream()
        if chunk.entity_path == "/events" and not chunk.is_static
        for r in chunk.to_record_batch().to_pylist()
    ]
