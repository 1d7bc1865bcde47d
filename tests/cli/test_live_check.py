"""`cananalyze live --check`: the sample sessions replayed over slcan on a pty, the rules
of samples/rules.yaml checked as the frames arrive, findings reported while the
session runs, `check`'s report and exit codes at the end, and an .rrd streamed
during the session readable after Ctrl-C."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from conftest import SAMPLES
from helpers.live_slcan import start_live
from junitparser import JUnitXml

from cananalyze.api.capture import load
from cananalyze.sim.slcan_replay import replay

RULES = SAMPLES / "rules.yaml"
NETWORK = SAMPLES / "network.toml"


def _read_rrd(path) -> dict[str, list[dict]]:
    from rerun.chunk import RrdReader

    rows: dict[str, list[dict]] = {}
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            rows.setdefault(chunk.entity_path, []).extend(chunk.to_record_batch().to_pylist())
    return rows


class _Lines:
    """Collects the child's stdout lines with the time each arrived."""

    def __init__(self, stream) -> None:
        self.lines: list[tuple[float, str]] = []
        self._t = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._t.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append((time.monotonic(), line.rstrip("\n")))

    def join(self) -> list[str]:
        self._t.join(timeout=30)
        return [x for _, x in self.lines]


def _run(log, args, tmp_path):
    """Replay `log` into a live session with args, SIGINT it; (rc, lines, stderr, t_replay_end)."""
    proc, adapter, _ = start_live(["--plain", *args], cwd=tmp_path)
    out = _Lines(proc.stdout)
    sent = replay(adapter, str(log), timed=True)
    t_end = time.monotonic()
    time.sleep(0.5)
    if proc.poll() is not None:  # the session ended by itself: say why
        raise AssertionError(f"live exited early ({proc.returncode}): {proc.stderr.read()[-2000:]}")
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=30)
    lines = out.join()
    err = proc.stderr.read()
    return proc.returncode, lines, err, t_end, sent, out.lines


@pytest.mark.slow
def test_faults_found_live_with_report_exit_1_and_rrd(tmp_path):
    junit, js, rrd = tmp_path / "r.xml", tmp_path / "f.json", tmp_path / "live.rrd"
    rc, lines, err, t_end, sent, timed = _run(
        SAMPLES / "faults.log",
        ["--check", str(RULES), "--network", str(NETWORK)]
        + ["--junit", str(junit), "--json", str(js), "--rrd", str(rrd)],
        tmp_path,
    )
    assert rc == 1, err
    assert "Traceback" not in err
    assert sent == 930  # 933 frames less the 3 error frames slcan cannot carry

    # the findings stream with the frames while the session runs
    # (under the frame that showed them, or on a line of their own: a deadline the tick saw)
    # (in the order of the output, not by the wall clock: a loaded machine only delays both)
    live = [(t, x) for t, x in timed if re.match(r"(    └─ |\s*\d+\.\d{6}  )?(ERROR|WARNING) ", x)]
    order = [x for _, x in timed]
    hit = next(
        i for i, x in enumerate(order) if "assert_signal: ch3 = 3276.7 outside -200..850" in x
    )
    frame_at = [re.match(r"\s*(\d+\.\d{6})  ", x) for x in order]
    later = [i for i, m in enumerate(frame_at) if m and float(m.group(1)) >= 7.0]
    assert later and hit < later[0]  # ch3 breaks 4 s into a 10 s log: shown before 7 s's frames
    # node 6's 1.6 s silence, seen while it lasted (the rest of the bus talks on)
    assert any(
        re.search(
            r"heartbeat: (node 6 )?heartbeat (stopped: none since \+4\.\d{3} s|dropout: no heartbeat for 1)",
            x,
        )
        for _, x in live
    )

    # at the end: check's report (findings, verdict line), JUnit and JSON
    verdict = [x for x in lines if re.match(r"\d+ rules \(", x)]
    assert len(verdict) == 1
    findings = json.loads(js.read_text())
    # notes: only guard requests the replay's jitter brought early (info, not a fault)
    notes = [f for f in findings if f["severity"] == "info"]
    assert verdict[0].endswith(f" {len(notes)} note(s)")
    assert all(f["rule"] == "guarding" and "faster" in f["message"] for f in notes)
    assert len(findings) - len(notes) == int(verdict[0].split(": ")[1].split()[0])
    got = {(f["rule"], f["node"]) for f in findings}
    # the faults the scenario injects (samples/README.md); timing jitter on a busy machine
    # may add more, so these must be there, not only these
    assert {
        ("emcy", 3),
        ("emcy", 7),
        ("assert_signal", 5),
        ("heartbeat", 6),
        ("assert_heartbeat", 6),
        ("pdo_async", 3),
        ("sdo", 3),
        ("sdo", 5),
    } <= got
    # ... and once, completed with the whole gap when node 6 came back
    # (a loaded machine may add jitter findings of its own, never a second one for this gap)
    hb6 = [
        f for f in findings if f["rule"] == "heartbeat" and f["node"] == 6 and f["measured"] > 1000
    ]  # by its length, not its time: a loaded machine shifts a live session's receive times
    assert len(hb6) == 1 and hb6[0]["measured"] > 1500
    assert hb6[0]["message"].startswith("heartbeat dropout: no heartbeat for ")
    emcy = sorted(f["measured"] for f in findings if f["rule"] == "emcy" and f["node"] == 3)
    assert emcy == ["0x8100", "0x8130", "0x8140"]
    sdo = {f["message"] for f in findings if f["rule"] == "sdo" and " took " not in f["message"]}
    # the master gives up on 0x1008 after exactly 1 s, the tracker's timeout: which one is
    # seen first depends on microseconds of jitter, both say the read failed
    assert sdo - {"SDO upload 0x1008:00 abort: SDO protocol timed out"} == {
        "SDO download 0x1018:01 abort: Attempt to write a read only object",
        "SDO upload 0x2FFF:00 abort: Object does not exist in the object dictionary",
    } | (
        {
            "SDO upload 0x1008:00 timeout: no frame within 1 s while waiting for the initiate response"
        }
        & sdo
    )
    assert any(m.startswith("SDO upload 0x1008:00 ") for m in sdo)
    assert ("error_frames", None) not in got  # slcan delivered none
    for f in findings:
        shown = _shown(f["t_rel"])
        assert any(x.startswith(shown) and f["message"] in x for x in lines), f
    suite = next(iter(JUnitXml.fromfile(str(junit))))
    failed = {c.name for c in suite if c.result}
    assert {"assert_signal node 5", "heartbeat node 6", "emcy node 3"} <= failed
    assert "frames: 930" in lines

    # the .rrd streamed during the session is complete after the SIGINT: the same
    # PDO values as the offline export of the log
    assert f"wrote {rrd}" in err
    rows = _read_rrd(rrd)
    cap = load(SAMPLES / "faults.log", network=NETWORK)
    for s in cap.series:
        for name, values in s.columns.items():
            path = f"/node/{s.node}/{s.pdo}/{name}"
            live_values = [r["Scalars:scalars"][0] for r in rows[path]]
            np.testing.assert_allclose(live_values, np.asarray(values, float))
    assert max(r["Scalars:scalars"][0] for r in rows["/node/5/tpdo2/ch3"]) == pytest.approx(3276.7)
    for node in (3, 5, 6, 7):
        states = [r["StateChange:state"][0] for r in rows[f"/node/{node}/nmt"]]
        assert states == [e.message for e in cap.state_changes if e.node == node]
        assert states[-1] == "operational"
    texts = [r["TextLog:text"][0] for r in rows["/events"]]
    assert any("[assert_signal] ch3 = 3276.7" in t for t in texts)
    levels = {r["TextLog:level"][0] for r in rows["/events"]}
    assert {"INFO", "ERROR"} <= levels
    assert len(rows["/bus/load"]) >= 95  # 0.1 s windows over a ~10 s session


@pytest.mark.slow
def test_commissioning_passes_live_exit_0(tmp_path):
    """The live pipeline adds no finding of its own: every finding of the session is one
    that `check` finds offline in the frames the session recorded (their times are the
    host's: a replay over a pty on a loaded machine moves frames by tens of ms, even
    stalls 250 ms, and those gaps are then really in what was seen), except the
    session's end, when the bus falls silent before Ctrl-C. On an unloaded run both
    are empty and the exit code is 0."""
    js, rec = tmp_path / "f.json", tmp_path / "seen.log"
    args = ["--check", str(RULES), "--network", str(NETWORK), "--json", str(js)]
    rc, lines, err, _, sent, _ = _run(
        SAMPLES / "commissioning.log", [*args, "--record", str(rec)], tmp_path
    )
    assert sent == 1200
    # the replay's end is the bus falling silent before Ctrl-C: the session may say so on
    # the wall clock (each overdue deadline, from the last frame on), and nothing else
    findings = json.loads(js.read_text())
    silent_since = [
        (f, float(m.group(1)))
        for f in findings
        if (
            m := re.search(
                r"; no frame from any node since \+(\d+\.\d+) s \(the adapter", f["message"]
            )
        )
    ]
    # the bus's last silence (a stall of the replay midway is a silence too, seen as such)
    end = max((t for _, t in silent_since), default=None)
    quiet = [f for f, t in silent_since if t == end and f["t_rel"] >= t]
    offline_js = tmp_path / "offline.json"
    offline = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(rec), "--rules", str(RULES)]
        + ["--network", str(NETWORK), "--json", str(offline_js), "-q"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert offline.returncode in (0, 1), offline.stderr
    seen = json.loads(offline_js.read_text())

    # the same findings: rule and node alike, each at about the same time (a deadline the
    # session saw pass on the wall clock is told when it passed; offline, at the frame
    # that ended the gap)
    live = sorted((f["rule"], f["node"], f["t_rel"]) for f in findings if f not in quiet)
    offline = sorted((f["rule"], f["node"], f["t_rel"]) for f in seen)
    assert [x[:2] for x in live] == [x[:2] for x in offline], (live, offline)
    assert all(abs(a[2] - b[2]) < 0.5 for a, b in zip(live, offline, strict=True))
    # the rules that do not depend on timing find nothing in the sample, live or offline
    timing = {"heartbeat", "assert_heartbeat", "sync", "guarding", "pdo_async", "pdo_sync"}
    timing |= {"assert_pdo_rate", "assert_operational", "sdo"}  # sdo: an answer past 5 ms
    assert not [f for f in seen if f["rule"] not in timing], seen
    notes = sum(f["severity"] == "info" for f in findings)
    assert rc == (1 if len(findings) > notes else 0), err
    assert re.match(r"\d+ rules \(", lines[-1]) and lines[-1].endswith(
        f": {len(findings) - notes} violation(s), {notes} note(s)"
    )
    assert "frames: 1200" in lines


def test_report_options_need_check(tmp_path):
    from conftest import ROOT

    proc = subprocess.run(
        [sys.executable, "-m", "cananalyze", "live", "-i", "virtual", "-c", "x", "--junit", "j"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("cananalyze: error:") and "--check" in proc.stderr


def _shown(t_rel: float) -> tuple[str, ...]:
    """How the terminal may show a finding whose JSON t_rel is rounded to the µs: the
    terminal formats the unrounded time to the ms, so a time within half a µs of a half
    millisecond shows on either side (live times are host clock floats: a few findings
    in a thousand, which made this test fail now and then)."""
    return tuple({f"{t_rel + d:+.3f} s " for d in (-5e-7, 0.0, 5e-7)})
