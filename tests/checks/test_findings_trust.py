"""Findings you can trust (issue 20): the configuration followed while the bus runs,
logs without timestamps, one finding per fault, the terminal cap, real-stack tolerances,
EMCY findings in the device's words."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest
from conftest import real_file

import cananalyze
from cananalyze.core.frames import FLAG_RTR, from_rows
from cananalyze.formats.logfile import write_log
from tests.helpers import config_traffic


def _check_rows(tmp_path, rows, rules_text: str):
    log = tmp_path / "traffic.log"
    write_log(from_rows(sorted(rows, key=lambda r: r[0])), log)
    rules = tmp_path / "rules.yaml"
    rules.write_text(rules_text)
    return log, rules, cananalyze.check(log, rules=rules)


# --- python-canopen traffic whose configuration changes while the bus runs -----------
def _late_heartbeats(rows, declared_ms: float | None, jitter_ms: float) -> tuple[set, set]:
    """What the recorded traffic itself says of node 5's heartbeat, read straight from the
    frames (independent of the checks): (gaps that are late, gaps that are in time), each
    gap as (time of the late heartbeat, gap in ms).

    The period in force follows CiA 301: the declared value (None: nothing declared, the
    checks learn one, gaps not judged here), 0x1017 as an SDO download confirms it, the
    declared value again after an NMT reset and boot-up. Gaps across a
    change, a reset or a boot-up, and gaps within 5 ms of the limit, are in neither set.
    python-canopen runs on threads, so a loaded machine can really delay a heartbeat:
    such a gap is late in the traffic, and then a finding is right, not false."""
    node, period, last, changed = config_traffic.NODE, declared_ms, None, False
    late, on_time = set(), set()
    pending = None  # 0x1017 value of a download request waiting for its response
    for t, cob, data, _flags in sorted(rows, key=lambda r: r[0]):
        if cob == 0x600 + node and data[:4] == b"\x2b\x17\x10\x00":
            pending = int.from_bytes(data[4:6], "little")
        elif cob == 0x580 + node and data[:4] == b"\x60\x17\x10\x00" and pending is not None:
            period, pending, changed = pending, None, True
        elif cob == 0x000 and data[:1] == b"\x81" and data[1:2] in (b"\x00", bytes([node])):
            period, last = declared_ms, None  # rebooting: no heartbeat due until boot-up
        elif cob == 0x700 + node and data[:1] == b"\x00":
            last, changed = None, False  # boot-up: the next gap starts at the next heartbeat
        elif cob == 0x700 + node and data and not _flags & FLAG_RTR:
            if last is not None and period and not changed:
                gap = (t - last) * 1000
                limit = period + max(0.1 * period, jitter_ms)
                if gap > limit + 5:
                    late.add((t, gap))
                elif gap < limit - 5:
                    on_time.add((t, gap))
            last, changed = t, False
    return late, on_time


@pytest.mark.parametrize("name", sorted(config_traffic.SCENARIOS))
@pytest.mark.slow
def test_configuration_changes_give_no_false_finding(name, tmp_path):
    rows, rules_text = config_traffic.SCENARIOS[name]()
    log, rules, found = _check_rows(tmp_path, rows, rules_text)
    declared = re.search(r"heartbeat_ms: (\d+)", rules_text)
    late, on_time = _late_heartbeats(
        rows, float(declared.group(1)) if declared else None, config_traffic.JITTER_MS
    )
    assert on_time, "the scenario recorded no heartbeat gap to judge"
    heartbeat = [f for f in found if f.rule == "heartbeat"]
    # each heartbeat finding is a gap the traffic shows late, with its length
    for f in heartbeat:
        assert any(abs(f.measured - gap) < 1.5 for _, gap in late), (f.message, sorted(late))
        assert not any(abs(f.measured - gap) < 1.5 for _, gap in on_time), f.message
    # and each late gap is found (on an idle machine there are none, and no finding)
    assert len(heartbeat) == len(late), ([f.message for f in heartbeat], sorted(late))
    assert [f.message for f in found if f.rule != "heartbeat"] == []
    cap = cananalyze.load(log, rules=rules)
    assert len(cap.frames) == len(rows) > 20


@pytest.mark.slow
def test_period_changed_by_sdo_a_late_heartbeat_is_still_found(tmp_path):
    """The same traffic with two heartbeats held back after the change to 100 ms: the one
    late gap (300 ms, past 100 ms and the scenario's 100 ms jitter floor) is found,
    judged by the written value, and says where that came from."""
    rows, rules_text = config_traffic.heartbeat_period_changed()
    hb = [r for r in rows if r[1] == 0x705 and r[2] != b"\x00"]
    write = next(r[0] for r in rows if r[1] == 0x605 and r[2][:3] == b"\x2b\x17\x10")
    after = [r for r in hb if r[0] > write + 0.5]
    dropped = after[2:4]
    log, _, found = _check_rows(tmp_path, [r for r in rows if r not in dropped], rules_text)
    (f,) = found
    assert f.rule == "heartbeat" and f.severity == "error"
    assert f.expected == 100 and 250 < f.measured < 400
    assert f.basis.startswith("0x1017 written at +")


def test_learned_period_is_per_segment_and_says_so(tmp_path):
    """Nothing configured: 100 ms learned before a reset, 1000 ms after; a 900 ms gap is
    a dropout in the first segment only, and the finding names its segment."""
    rows = [(0.0, 0x705, b"\x7f")]
    rows += [(0.1 * k, 0x705, b"\x05") for k in range(1, 20)]
    rows += [(2.8, 0x705, b"\x05")]  # 900 ms after the previous: a dropout at 100 ms
    rows += [(2.9, 0x705, b"\x05"), (3.0, 0x000, b"\x81\x05"), (3.05, 0x705, b"\x00")]
    rows += [(3.05 + k, 0x705, b"\x7f") for k in range(1, 9)]  # 1 s after the reset
    log = tmp_path / "learn.log"
    write_log(from_rows(rows), log)
    found = cananalyze.check(log)
    # the node stays pre-operational for 8 s after the reset: the boot rule tells it (info)
    assert [(x.rule, x.severity) for x in found if x.rule != "heartbeat"] == [("boot", "info")]
    (f,) = [x for x in found if x.rule == "heartbeat"]
    assert f.rule == "heartbeat" and f.severity == "warning" and f.t == pytest.approx(1.9)
    assert f.expected == pytest.approx(100.0)
    assert f.basis == "learned from the log's median over +0.000 s..+2.900 s"


@pytest.mark.parametrize("declared", [False, True])
@pytest.mark.parametrize(
    "target, boot_s, dropout",
    [(0, 0.45, False), (5, 0.45, False), (9, 0.45, True), (0, 12.0, True), (5, 12.0, True)],
)
def test_an_nmt_reset_gives_the_node_time_to_boot(tmp_path, declared, target, boot_s, dropout):
    """Node 5 beats every 100 ms (learned from the log, or declared in the network file).
    An NMT reset to it or to all nodes (node-ID 0) stops its heartbeat until its boot-up
    (CiA 301), which answers a reset within 10 s (RESET_ANSWER_S): a boot-up 450 ms
    after the reset is no dropout. It was one for the reset to all when the period was
    learned (the node was known only by its heartbeat), and for both resets when it was
    declared. A reset of another node, or a boot-up 12 s later, is still a dropout."""
    rows = [(0.1 * k, 0x705, b"\x05") for k in range(10)]
    boot = 0.95 + boot_s
    rows += [(0.95, 0x000, bytes([0x81, target])), (boot, 0x705, b"\x00")]
    rows += [(boot + 0.1 * k, 0x705, b"\x7f") for k in range(1, 10)]
    log = tmp_path / "reset.log"
    write_log(from_rows(rows), log)
    net = tmp_path / "net.toml"
    net.write_text("[nodes.5]\nheartbeat_ms = 100\n" if declared else "")
    found = [f for f in cananalyze.check(log, network=net) if f.rule == "heartbeat"]
    assert len(found) == dropout
    if dropout:
        (f,) = found
        assert f.t == pytest.approx(0.9) and f.expected == pytest.approx(100.0)
        assert f.measured == pytest.approx((boot + 0.1 - 0.9) * 1000)


def test_frames_sharing_a_time_stamp_teach_no_period(tmp_path):
    """Heartbeats three to a time stamp (a coarse logger clock): the zero gaps are no period.
    Their median (0 ms) made every real gap of the 100 ms producer a "dropout"; the
    positive gaps teach 100 ms, and only the one 900 ms gap is late."""
    rows = [(0.0, 0x705, b"\x7f")]
    for k in range(1, 30):
        t = 0.1 * k + (0.8 if k > 20 else 0.0)
        rows += [(t, 0x705, b"\x05")] * 3
    log = tmp_path / "pairs.log"
    write_log(from_rows(rows), log)
    (f,) = [f for f in cananalyze.check(log) if f.rule == "heartbeat"]
    assert f.expected == pytest.approx(100.0) and f.measured == pytest.approx(900.0)


def test_real_vehicle_log_no_dropout_against_a_zero_period():
    """SavvyCAN's GVRET log (vehicle traffic, not CANopen): 0x754 comes in bursts of
    frames at one time; it gave 164 "heartbeat dropouts" judged against a learned 0 ms,
    then 3 judged against a positive period. Those frames are 8 bytes: no heartbeat at
    all (CiA 301: 1 byte; `errctl_length` names them), so no heartbeat finding. The
    zero gaps themselves: test_frames_sharing_a_time_stamp_teach_no_period above."""
    found = cananalyze.check(real_file("collin80__SavvyCAN/GVRET_Log.csv"))
    assert [f for f in found if f.rule == "heartbeat"] == []
    assert 0x754 in {f.cob_id for f in found if f.rule == "errctl_length"}


# --- logs without timestamps ----------------------------------------------------------
def test_untimed_real_log_says_so_once_and_skips_timing():
    log = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    found = cananalyze.check(log)
    (note,) = found
    assert note.severity == "info" and note.rule == "timestamps"
    assert note.message.startswith(
        "no timestamps: timing rules skipped (heartbeat, pdo_async, drive_command)"
    )


def test_untimed_log_of_two_buses_says_so_for_the_log_not_a_bus(tmp_path):
    """A screen-format candump of can0 and can1 without times: one "no timestamps" note,
    naming no bus (it is the whole log's), beside findings that each name their bus."""
    rows = [("can0", 0x705, b"\x7f"), ("can0", 0x185, b"\x01\x02")]  # PDO, pre-operational
    rows += [("can1", 0x706, b"\x7f"), ("can1", 0x186, b"\x01\x02")]
    log = tmp_path / "two.txt"
    log.write_text("".join(
        f"  {bus}  {cid:03X}   [{len(d)}]  {' '.join(f'{b:02X}' for b in d)}\n"
        for bus, cid, d in rows))  # fmt: skip
    found = cananalyze.check(log)
    assert [(f.rule, f.bus) for f in found if f.rule == "timestamps"] == [("timestamps", None)]
    assert {(f.rule, f.bus) for f in found if f.rule != "timestamps"} == {
        ("pdo_not_operational", "can0"), ("pdo_not_operational", "can1")}  # fmt: skip
    subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(log), "--json", str(tmp_path / "f.json")],
        capture_output=True, text=True,
    )  # fmt: skip
    got = json.loads((tmp_path / "f.json").read_text())
    assert [x.get("bus") for x in got if x["rule"] == "timestamps"] == [None]
    assert sorted(x.get("bus") for x in got if x["rule"] != "timestamps") == ["can0", "can1"]


def test_untimed_log_keeps_order_based_rules_in_line_order(tmp_path):
    """All at t = 0: a PDO before the node is started, a boot-up with no reset, an SDO
    abort are still found, at their lines; the final "stop all" judges nothing before it."""
    rows = [(0.0, 0x705, b"\x7f"), (0.0, 0x185, b"\x01\x02")]  # PDO while pre-operational
    rows += [(0.0, 0x000, b"\x01\x00")]  # start all
    rows += [(0.0, 0x185, b"\x01\x02")] * 5 + [(0.0, 0x080, b"")] * 5
    rows += [
        (0.0, 0x605, b"\x40\x00\x10\x00\0\0\0\0"),
        (0.0, 0x585, b"\x80\x00\x10\x00\0\0\x02\x06"),
    ]
    rows += [(0.0, 0x705, b"\x00")]  # boot-up, no reset: unexpected
    rows += [(0.0, 0x000, b"\x02\x00")]  # stop all, at the end
    lines = [
        f"  can0  {cid:03X}   [{len(d)}]  {' '.join(f'{b:02X}' for b in d)}" for _, cid, d in rows
    ]
    log = tmp_path / "screen.txt"
    log.write_text("\n".join(lines) + "\n")
    found = cananalyze.check(log)
    got = [(f.rule, f.line) for f in found]
    assert got[0] == ("timestamps", 1)
    assert ("pdo_not_operational", 2) in got
    assert ("sdo", 15) in got
    assert ("unexpected_bootup", 16) in got
    assert len(got) == 4  # no PDO is judged by the "stop all" on line 17
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(log), "-q"],
        capture_output=True,
        text=True,
    ).stdout
    assert "line 16 node 5 0x705 [error] unexpected_bootup" in out


# --- one finding per fault, the cap on the terminal only -------------------------------
def _emcy_storm(tmp_path, n: int = 38):
    rows = [(0.0, 0x705, b"\x7f"), (0.05, 0x000, b"\x01\x05")]
    rows += [(0.1 + 0.1 * k, 0x085, bytes([0x10, 0x32, 0x05, 0, 0, 0, 0, 0])) for k in range(n)]
    log = tmp_path / "storm.log"
    write_log(from_rows(rows), log)
    return log


def test_machine_outputs_carry_every_finding_terminal_counts_right(tmp_path):
    log = _emcy_storm(tmp_path, 38)
    out = tmp_path / "f.json"
    junit = tmp_path / "f.xml"
    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(log), "-q", "--json", str(out)]
        + ["--junit", str(junit)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 1
    rows = json.loads(out.read_text())
    emcy = [r for r in rows if r["rule"] == "emcy"]
    assert len(emcy) == 39  # 38 frames, and the error still active at the end
    assert not any("more like this" in r["message"] for r in rows)
    from junitparser import JUnitXml

    (case,) = [c for s in JUnitXml.fromfile(str(junit)) for c in s if c.name == "emcy node 5"]
    assert case.result[0].message.startswith("39 finding(s)")
    lines = done.stdout.splitlines()
    shown = [line for line in lines if "[warning] emcy: EMCY" in line]
    assert len(shown) == 21  # the first 20, and the end-of-log one never hidden
    assert any("still active at the end of the log" in line for line in shown)
    (more,) = [line for line in lines if "more like this" in line]
    assert "18 more like this not shown (38 in all;" in more  # one per frame
    assert cananalyze.load(log).findings.rule.eq("emcy").sum() == 39


# --- defaults that match real stacks ----------------------------------------------------
def test_event_timer_jitter_under_the_floor_is_not_a_violation(tmp_path):
    rows = [(0.0, 0x705, b"\x7f"), (0.01, 0x000, b"\x01\x05")]
    t = 0.02
    for k in range(50):
        t += 0.0118 if k % 3 == 0 else 0.0101  # 11.8 ms now and then against 10 ms
        rows.append((t, 0x185, b"\x01\x02"))
    rows.append((t + 0.013, 0x185, b"\x01\x02"))  # 13 ms: past the 2 ms floor
    net = "nodes:\n  5:\n    tpdo:\n      1: {transmission_type: 255, event_timer: 10, length: 2}\n"
    netfile = tmp_path / "net.yaml"
    netfile.write_text(net)
    log = tmp_path / "et.log"
    write_log(from_rows(rows), log)
    found = cananalyze.check(log, network=netfile)
    assert [(f.rule, f.measured) for f in found] == [("pdo_async", 13.0)]
    assert found[0].basis == "0x1800:5 in the network file"
    rules = tmp_path / "rules.yaml"
    rules.write_text("rules:\n  pdo_async: {jitter_ms: 5}\n")
    assert cananalyze.check(log, network=netfile, rules=rules) == []


def test_guard_requests_faster_than_the_guard_time_are_information(tmp_path):
    rows = []
    t, toggle = 0.1, 0
    for _ in range(10):
        rows += [(t, 0x70A, b"", FLAG_RTR), (t + 0.001, 0x70A, bytes([0x7F | toggle]))]
        toggle ^= 0x80
        t += 0.05  # every 50 ms against a 100 ms guard time
    netfile = tmp_path / "net.yaml"
    netfile.write_text("nodes:\n  10: {guard_time_ms: 100, life_time_factor: 3}\n")
    log = tmp_path / "guard.log"
    write_log(from_rows(rows), log)
    found = cananalyze.check(log, network=netfile)
    assert found and {f.severity for f in found} == {"info"}
    assert "faster" in found[0].message and found[0].basis == "0x100C in the network file"


# --- EMCY findings in the device's words -----------------------------------------------
def test_emcy_finding_carries_the_manufacturer_meaning(tmp_path):
    from cananalyze.devices.builtin import load_builtin

    profile = load_builtin("mcb560")
    data = bytes([0x00, 0xFF, 0x81, 0x00, 0x01, 0x00, 0x00, 0x80])  # Chip-EC 0x80000001
    assert profile.decode_emcy(0xFF00, 0x81, data[3:8])["flags"] == ["bus off", "output overload"]
    meaning = "(bus off, output overload)"
    rows = [(0.0, 0x701, b"\x7f"), (0.1, 0x081, data)]
    log = tmp_path / "emcy.log"
    write_log(from_rows(rows), log)
    found = cananalyze.check(log, device={1: "mcb560"})
    emcy = [f for f in found if f.rule == "emcy"]
    assert emcy and all(str(meaning) in f.message for f in emcy)
    decoded = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--device", "1=mcb560"],
        capture_output=True,
        text=True,
    ).stdout
    assert str(meaning) in decoded


def test_real_pcan1_one_finding_per_gap_and_none_while_a_node_reboots():
    """hilch pcan1.trc: node 40's 19.2 s silence is one finding (before: an error and a
    warning), judged against the period learned before it; node 15's silences each begin
    with an NMT reset of node 15 (it is rebooting: no heartbeat is due until its boot-up),
    where the whole-log median used to give three false dropouts."""
    log = real_file("hilch__canopen-message-interpreter/pcan1.trc")
    hb = [f for f in cananalyze.check(log) if f.rule == "heartbeat"]
    (f,) = [f for f in hb if f.node == 40]
    assert f.t_rel == pytest.approx(91.823, abs=1e-3) and f.severity == "warning"
    assert f.basis.startswith("learned from the log's median over +0.000 s..")
    assert f.expected == pytest.approx(1009, abs=5)
    assert [f for f in hb if f.node == 15] == []


def test_event_timer_judged_on_a_node_whose_nmt_state_the_log_never_shows(tmp_path):
    """The Axiomatic I/O module's log has no boot-up, heartbeat or NMT command: its TPDOs
    show it operational (CiA 301 sends PDOs only then). Declared at 20 ms, its 100 ms TPDO1
    is late every time; an NMT stop of the node in the log ends the judging."""
    log = real_file("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log")
    net = tmp_path / "net.toml"
    net.write_text("[nodes.127.tpdo.1]\ncob_id = 0x1FF\nevent_timer = 20\n")
    late = [f for f in cananalyze.check(log, network=net) if f.rule == "pdo_async"]
    assert len(late) > 5000 and {f.cob_id for f in late} == {0x1FF}
    assert all(95 <= f.measured <= 102 and f.expected == 20 for f in late)
    # the same log with the node stopped after its first second: nothing after the stop
    lines = log.read_text().splitlines()
    t0 = float(lines[0].split(")")[0][1:])
    stop = f"({t0 + 1.0:.6f}) can0 000#027F"
    cut = next(i for i, x in enumerate(lines) if float(x.split(")")[0][1:]) > t0 + 1.0)
    stopped = tmp_path / "stopped.log"
    stopped.write_text("\n".join([*lines[:cut], stop, *lines[cut:]]) + "\n")
    late = [f for f in cananalyze.check(stopped, network=net) if f.rule == "pdo_async"]
    assert late and max(f.t for f in late) < t0 + 1.0
