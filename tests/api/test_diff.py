"""`cananalyze diff A B`: two runs compared per node; exit 0 same, 1 different, 2 error.

The faulty sample network against the healthy one must name each fault injected
(samples/README.md's table), a log against itself nothing, a log against its own DCF
(`od --dcf`) nothing and against an edited DCF the edited object; timings within the
tolerance are the same.
"""

from __future__ import annotations

import configparser
import json
import subprocess
import sys

import pytest

from tests.conftest import SAMPLES, real_file

NETWORK, RULES = SAMPLES / "network.toml", SAMPLES / "rules.yaml"


def _diff(*args) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", "diff", *map(str, args)],
        capture_output=True,
        text=True,
    )


def _json(*args) -> tuple[int, dict]:
    run = _diff(*args, "--json", "-")
    assert run.returncode in (0, 1), run.stderr
    return run.returncode, json.loads(run.stdout)


@pytest.mark.parametrize("log", ["commissioning.log", "faults.blf", "demo.asc"])
def test_a_log_against_itself_is_the_same(log):
    run = _diff(SAMPLES / log, SAMPLES / log)
    assert run.returncode == 0, run.stdout + run.stderr
    assert run.stdout.endswith("same within tolerances\n")


def test_the_same_run_in_two_formats_is_the_same():
    """candump and BLF of one simulated run: the same frames, so no difference."""
    rc, doc = _json(SAMPLES / "faults.log", SAMPLES / "faults.blf", "--network", NETWORK)
    assert (rc, doc["same"], doc["differences"]) == (0, True, [])


def test_each_injected_fault_is_named():
    rc, doc = _json(
        SAMPLES / "commissioning.log",
        SAMPLES / "faults.log",
        "--network",
        NETWORK,
        "--rules",
        RULES,
    )
    assert rc == 1 and not doc["same"]
    got = {(d["node"], d["section"], d["item"]): (d["a"], d["b"]) for d in doc["differences"]}
    # EMCY from the MCB-560 (node 3) and the I-7231D (node 7); the reset 0x0000 is none
    assert got[("3", "emcy", "codes")] == (None, ["0x8100", "0x8130", "0x8140"])
    assert got[("7", "emcy", "codes")] == (None, ["0xFF00"])
    assert got[("network", "findings", "error frames")] == (None, 3)
    # DAT 7014 ch3 over range: the rules file's signal assertion
    assert got[("5", "findings", "assert_signal error")] == (None, 3)
    # DAT 7130's heartbeat stops for 1.6 s
    assert got[("6", "timing", "heartbeat max ms")] == (100.0, 1600.0)
    assert got[("6", "findings", "heartbeat error")] == (None, 1)
    # MCB-560 TPDO1 twice within its inhibit time, TPDO2's event timer stalls
    assert got[("3", "findings", "pdo_async error")] == (None, 2)
    # SDO aborts on nodes 3 and 5, and node 5's timeout
    assert got[("3", "findings", "sdo error")] == (None, 1)
    assert got[("5", "findings", "sdo error")] == (None, 2)
    # identity read in the healthy run only: unknown in the faulty one, not a difference
    assert not any(section == "identity" for _, section, _ in got)


def test_an_object_named_apart_in_two_runs_is_one_item():
    """Without a network file the healthy run names node 5's objects by its profile (its
    identity is read) and the faulty one generically: the same object and value are no
    difference, and an object is never listed twice."""
    rc, doc = _json(SAMPLES / "commissioning.log", SAMPLES / "faults.log")
    conf = [(d["node"], d["item"].split()[0]) for d in doc["differences"]]
    conf = [
        c for c, d in zip(conf, doc["differences"], strict=True) if d["section"] == "configuration"
    ]
    assert conf and len(conf) == len(set(conf))
    assert ("5", "0x1A01:01") not in conf and ("3", "0x1800:03") not in conf


def test_text_groups_by_node(tmp_path):
    run = _diff(SAMPLES / "commissioning.log", SAMPLES / "faults.log", "--network", NETWORK)
    assert run.returncode == 1
    out = run.stdout.splitlines()
    assert out[:2] == [f"A: {SAMPLES / 'commissioning.log'}", f"B: {SAMPLES / 'faults.log'}"]
    node7 = out.index("node 7:")
    assert "  emcy: codes: (none) -> 0xFF00" in out[node7:]
    assert out[-1].endswith("difference(s)")


def _heartbeats(path, period_ms: int, extra: str = "") -> None:
    lines = [f"({k * period_ms / 1000:.6f}) vcan0 705#05" for k in range(50)]
    path.write_text("\n".join(lines) + "\n" + extra)


def test_timing_within_the_tolerance_is_the_same(tmp_path):
    a, b, c = tmp_path / "a.log", tmp_path / "b.log", tmp_path / "c.log"
    _heartbeats(a, 100)
    _heartbeats(b, 105)  # 5 %: within the default 10 %
    _heartbeats(c, 130)
    assert _diff(a, b).returncode == 0
    rc, doc = _json(a, c)
    assert rc == 1
    assert {(d["item"], d["a"], d["b"]) for d in doc["differences"]} == {
        ("heartbeat median ms", 100.0, 130.0),
        ("heartbeat max ms", 100.0, 130.0),
    }
    assert _diff(a, c, "--tolerance", "0.5").returncode == 0


def test_a_dcf_as_the_reference(tmp_path):
    """The log against its own configuration (`od --dcf`): the same; against the DCF
    with 0x1017 edited to 250 ms: that object, exit 1."""
    log = SAMPLES / "commissioning.log"
    subprocess.run(
        [sys.executable, "-m", "cananalyze", "od", str(log), "--dcf", str(tmp_path), "-q"],
        check=True,
        capture_output=True,
    )
    dcf = tmp_path / "node5.dcf"
    run = _diff(log, dcf)
    assert run.returncode == 0, run.stdout + run.stderr
    ini = configparser.RawConfigParser()
    ini.optionxform = str
    ini.read(dcf)
    ini.set("1017", "ParameterValue", "0xFA")
    edited = tmp_path / "edited.dcf"
    with open(edited, "w") as f:
        ini.write(f)
    rc, doc = _json(log, edited)
    assert rc == 1
    assert [(d["node"], d["item"], d["a"], d["b"]) for d in doc["differences"]] == [
        ("5", "0x1017:00 Producer heartbeat time", "100", "250")
    ]


def test_two_real_logs_of_one_network():
    """hilch's pcan1 and pcan2 traces: the same node 15, another product and firmware,
    its TPDOs remapped, node 10 in the second only."""
    a = real_file("hilch__canopen-message-interpreter/pcan1.trc")
    b = real_file("hilch__canopen-message-interpreter/pcan2.trc")
    rc, doc = _json(a, b)
    assert rc == 1
    got = {(d["node"], d["section"], d["item"]): (d["a"], d["b"]) for d in doc["differences"]}
    assert got[("15", "identity", "device_type")] == (4026532422, 4026532423)
    assert got[("15", "configuration", "0x1A00:00 TPDO1 mapping: number of entries")] == (
        "6 (6 entries mapped)",
        "5 (5 entries mapped)",
    )
    assert got[("10", "nodes", "node seen")] == (False, True)
    assert _diff(a, a).returncode == 0


def test_bad_input_is_one_line_and_exit_2(tmp_path):
    run = _diff(tmp_path / "missing.log", SAMPLES / "demo.log")
    assert run.returncode == 2
    assert len(run.stderr.strip().splitlines()) == 1 and "missing.log" in run.stderr
