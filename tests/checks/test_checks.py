"""Checks: logs with deliberate violations of every rule, each found at the right time."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
import yaml

from cananalyze.api.assertions import assert_heartbeat, assert_no_emcy, run_rules
from cananalyze.checks.build import build_checker
from cananalyze.checks.engine import Checker
from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_ERR, FLAG_RTR, from_rows
from cananalyze.formats.logfile import write_log
from cananalyze.formats.source import read_all
from cananalyze.pipeline import Decoder, Options, build_decoder

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "samples" / "demo.log"


def run(rows, network=None, rules=None, split=None):
    """Decode rows (optionally split into several batches) through the pipeline's decoder
    and a Checker; `network` is a network file's tree."""
    checker = Checker(rules)
    with tempfile.TemporaryDirectory() as tmp:
        net = Path(tmp) / "net.yaml"
        net.write_text(yaml.safe_dump(network or {}))
        dec = build_decoder(Options(network=net), checker)
    fb = from_rows(sorted(rows, key=lambda r: r[0]))
    cuts = [0, *(split or []), len(fb)]
    for a, b in zip(cuts, cuts[1:], strict=False):
        dec.decode(fb.take(slice(a, b)))
    dec.finish()
    return checker


def by_rule(checker, rule):
    return [f for f in checker.findings if f.rule == rule]


def hb(node, times, state=5):
    return [(t, 0x700 + node, bytes([state])) for t in times]


def boot_start(nodes):
    rows = [(0.0, 0x700 + n, b"\x00") for n in nodes]
    rows.append((0.01, 0x000, b"\x01\x00"))
    return rows


def test_demo_log_is_clean_but_for_its_emcy():
    checker = run_rules(DEMO, build_checker().rules)
    rules = {f.rule for f in checker}
    # the demo raises and clears one EMCY on node 3 and has one deliberate SDO abort
    assert rules == {"emcy", "sdo"}
    emcy, sdo = sorted(checker, key=lambda f: f.rule)
    assert emcy.node == 3 and emcy.measured == "0x8100"
    assert (
        sdo.node == 3 and sdo.measured == "0x06020000" and sdo.t == pytest.approx(1767225600.0355)
    )


def test_heartbeat_dropout_in_second_batch_and_stop():
    times = [0.1 * i for i in range(1, 31) if not 12 <= i <= 15] + [3.5]
    rows = boot_start([5]) + hb(5, times) + [(5.0, 0x080, b"")]
    c = run(rows, network={"nodes": {5: {"heartbeat_ms": 100}}}, split=[12])
    found = by_rule(c, "heartbeat")
    dropouts = [f for f in found if "dropout" in f.message]
    assert [round(f.t, 3) for f in dropouts] == [1.1, 3.0]
    assert dropouts[0].measured == pytest.approx(500.0)
    stopped = [f for f in found if "stopped" in f.message]
    assert len(stopped) == 1 and stopped[0].t == pytest.approx(3.6)


def test_heartbeat_inferred_without_config_is_a_warning():
    times = [0.1 * i for i in range(1, 30) if i not in (10, 11)]
    c = run(boot_start([4]) + hb(4, times))
    (f,) = by_rule(c, "heartbeat")
    assert (
        f.severity == "warning" and f.t == pytest.approx(0.9) and f.measured == pytest.approx(300.0)
    )


def test_heartbeat_consumer_expiry():
    times = [0.1, 0.2, 0.3, 0.65, 0.75]
    c = run(
        boot_start([5]) + hb(5, times),
        network={"nodes": {1: {"heartbeat_consumer": {5: 250}}}},  # 0x1017 not known
    )
    consumer = [f for f in by_rule(c, "heartbeat") if "consumer" in f.message]
    assert len(consumer) == 1 and consumer[0].t == pytest.approx(0.55)


def test_one_gap_is_one_finding_dropout_and_consumer_expiry():
    """A gap late for 0x1017 that also expires a consumer's 0x1016 is one fault: one
    finding naming both, and where each expectation came from."""
    times = [0.1, 0.2, 0.3, 0.65, 0.75]
    c = run(
        boot_start([5]) + hb(5, times),
        network={"nodes": {5: {"heartbeat_ms": 100}, 1: {"heartbeat_consumer": {5: 300}}}},
    )
    (f,) = by_rule(c, "heartbeat")
    assert f.t == pytest.approx(0.3) and f.measured == pytest.approx(350.0)
    assert "expired node 1's consumer time 300 ms" in f.message
    assert f.basis == "0x1017 in the network file"


def test_unexpected_bootup_but_not_after_reset():
    rows = boot_start([7]) + hb(7, [0.1, 0.2, 0.3]) + [(0.35, 0x707, b"\x00")]
    rows += [(0.5, 0x000, b"\x81\x07"), (0.6, 0x707, b"\x00")]
    c = run(rows)
    (f,) = by_rule(c, "unexpected_bootup")
    assert f.t == pytest.approx(0.35) and f.node == 7


def test_guarding_period_lifetime_missing_reply_and_toggle():
    rows = [(0.0, 0x70A, b"\x00")]
    t = 0.1
    toggles = [0x05, 0x85, 0x85, 0x05]  # third reply repeats the toggle
    for k, byte in enumerate(toggles):
        rows += [(t, 0x70A, b"", FLAG_RTR), (t + 0.001, 0x70A, bytes([byte]))]
        t += 0.1 if k != 1 else 0.13  # one late request
    rows += [(t, 0x70A, b"", FLAG_RTR)]  # unanswered
    rows += [(t + 0.5, 0x70A, b"", FLAG_RTR), (t + 0.501, 0x70A, b"\x85")]  # life time exceeded
    rows += [(t + 1.0, 0x080, b"")]
    c = run(rows, network={"nodes": {10: {"guard_time_ms": 100, "life_time_factor": 3}}})
    msgs = [(round(f.t, 3), f.message.split(":")[0].split(" ")[0]) for f in by_rule(c, "guarding")]
    assert (0.33, "guard") in msgs  # request period 130 ms vs 100
    assert any(
        m[1] == "guard" and "toggle" in f.message
        for m, f in zip(msgs, by_rule(c, "guarding"), strict=True)
    )
    assert any(
        "no reply" in f.message and f.t == pytest.approx(0.53) for f in by_rule(c, "guarding")
    )
    assert any("life time exceeded" in f.message for f in by_rule(c, "guarding"))
    toggle = [f for f in by_rule(c, "guarding") if "toggle" in f.message]
    assert len(toggle) == 1 and toggle[0].t == pytest.approx(0.331)


def test_sync_period_and_counter():
    rows = [(0.1 * i, 0x080, bytes([i])) for i in range(1, 10) if i != 5]
    rows += [(1.05, 0x080, bytes([10]))]
    c = run(rows, network={"sync": {"period_us": 100000}})
    period = [round(f.t, 3) for f in by_rule(c, "sync") if "period" in f.message]
    counter = [f for f in by_rule(c, "sync") if "counter" in f.message]
    assert period == [0.6, 1.05]
    assert len(counter) == 1 and counter[0].measured == 6 and counter[0].expected == 5


@pytest.mark.parametrize("one_frame_batches", [False, True])
def test_sync_pdo_every_nth_sync_in_window_and_type0(one_frame_batches):
    """Also with one frame per batch, as live sniffing feeds them (PDO batches without a SYNC)."""
    rows = boot_start([5])
    for i in range(1, 13):
        rows.append((0.1 * i, 0x080, b""))
        if i % 2 == 0 and i != 8:
            delay = 0.03 if i == 10 else 0.001
            rows.append((0.1 * i + delay, 0x185, b"\x01\x02"))
    rows += [(0.1 * 12 + 0.002, 0x285, b"\x00"), (0.1 * 12 + 0.003, 0x285, b"\x00")]  # type 0 twice
    net = {
        "sync": {"period_us": 100000, "window_us": 20000},
        "nodes": {
            5: {
                "tpdo": {
                    1: {"cob_id": 0x185, "transmission_type": 2, "length": 2},
                    2: {"cob_id": 0x285, "transmission_type": 0, "length": 1},
                }
            }
        },
    }
    c = run(rows, network=net, split=list(range(1, len(rows))) if one_frame_batches else [9])
    found = by_rule(c, "pdo_sync")
    # the PDO missing at SYNC 8 shows at the next one, 4 SYNCs after the previous
    assert [(f.cob_id, round(f.t, 3), f.measured) for f in found if "SYNCs" in f.message] == [
        (0x185, 1.03, 4)
    ]
    assert [(f.cob_id, round(f.t, 3)) for f in found if "window" in f.message] == [(0x185, 1.03)]
    assert [(f.cob_id, round(f.t, 3)) for f in found if "type 0" in f.message] == [(0x285, 1.203)]


def test_async_pdo_inhibit_and_event_timer():
    rows = boot_start([5]) + hb(5, [0.05 * i for i in range(1, 40)])
    pdo_t = [0.1, 0.2, 0.203, 0.3, 0.4, 0.8, 0.9]
    rows += [(t, 0x285, b"\x00\x00") for t in pdo_t]
    pdo = {"transmission_type": 254, "inhibit_time": 50, "event_timer": 100, "length": 2}
    net = {"nodes": {5: {"tpdo": {2: pdo}}}}
    c = run(rows, network=net)
    found = by_rule(c, "pdo_async")
    assert [(round(f.t, 3), "inhibit" in f.message) for f in found] == [(0.203, True), (0.4, False)]


def test_pdo_from_pre_operational_node_and_length():
    rows = [
        (0.0, 0x705, b"\x00"),
        (0.05, 0x185, b"\x01"),
        (0.1, 0x000, b"\x01\x05"),
        (0.2, 0x185, b"\x01"),
        (0.3, 0x000, b"\x02\x05"),
        (0.4, 0x185, b"\x01\x02\x03"),
    ]
    c = run(rows, network={"nodes": {5: {"tpdo": {1: {"cob_id": 0x185, "length": 1}}}}})
    assert [(round(f.t, 2), f.measured) for f in by_rule(c, "pdo_not_operational")] == [
        (0.05, "pre-operational"),
        (0.4, "stopped"),
    ]
    (f,) = by_rule(c, "pdo_length")
    assert f.t == pytest.approx(0.4) and f.measured == 3 and f.severity == "warning"


def test_unknown_cob_id_once_and_declared_ids_skipped():
    rows = [(0.1, 0x7F0, b"\x01"), (0.2, 0x7F0, b"\x01"), (0.3, 0x10A, b"")]
    c = run(rows, network={"known_cob_ids": [0x10A]})
    (f,) = by_rule(c, "unknown_cob_id")
    assert f.cob_id == 0x7F0 and f.t == pytest.approx(0.1)


@pytest.mark.parametrize("size", [None, 333])
def test_unknown_cob_ids_past_the_listed_ones_are_counted(tmp_path, size):
    """A log of 1500 distinct 29-bit identifiers (each twice; one declared in the network
    file): the first 1000 seen are listed one by one, the frames on the other 499 in one
    finding at the end (a finding per identifier took 390 MB for 200k frames). The
    same whichever batch an identifier first comes in."""
    import random

    from exported import load_cut

    random.seed(7)
    ids = random.sample(range(0x800, 1 << 29), 1500)
    order = ids + ids[::-1]
    log = tmp_path / "ext.log"
    log.write_text("".join(f"({1 + k * 0.001:.6f}) can0 {i:08X}#01\n" for k, i in enumerate(order)))
    net = tmp_path / "net.toml"
    net.write_text(f"known_cob_ids = [{ids[10]}]\n")
    f = load_cut(log, size, network=net).findings
    f = f[f.rule == "unknown_cob_id"]
    listed = f[f.cob_id.notna()]
    assert listed.cob_id.astype(int).tolist() == [i for i in ids if i != ids[10]][:1000]
    (more,) = f[f.cob_id.isna()].itertuples()
    assert more.measured == 2 * 499  # both frames of each identifier not listed
    assert more.t == pytest.approx(1 + 1001 * 0.001)  # the first of them
    assert "998 more frames on unknown identifiers" in more.message


def test_emcy_raised_cleared_inhibit_active_at_end_and_short():
    e = 0x083
    rows = [
        (0.1, e, bytes.fromhex("1081010000000000")),
        (0.101, e, bytes.fromhex("0000000000000000")),
        (0.5, e, bytes.fromhex("3032040000000000")),
        (0.7, e, bytes.fromhex("0081")),
    ]
    c = run(rows, network={"nodes": {3: {"emcy_inhibit_time": 100}}})
    found = by_rule(c, "emcy")
    assert any("inhibit" in f.message and f.t == pytest.approx(0.101) for f in found)
    end = [f for f in found if "still active" in f.message]
    assert [f.measured for f in end] == ["0x3230"]
    assert any("2 data bytes" in f.message for f in found)
    with pytest.raises(AssertionError, match="0x8110"):
        assert_no_emcy(from_rows(rows))
    assert_no_emcy(from_rows(rows[:2]), allow=[0x8110])


def test_sdo_records_and_error_frames():
    fb = from_rows(
        [(0.1, 0x7E0, b"", FLAG_ERR), (0.2, 0x7E0, b"", FLAG_ERR), (0.3, 0x705, b"\x05")]
    )
    dec = Decoder()
    batch = dec.decode(fb)
    batch.add_record(
        2,
        {
            "kind": "sdo",
            "t": 0.3,
            "node": 5,
            "direction": "download",
            "index": 0x2000,
            "subindex": 1,
            "result": "abort",
            "abort_code": 0x06020000,
            "abort_text": "Object does not exist",
            "latency_ms": 80.0,
        },
    )
    from cananalyze.checks.rules.error_frames import ErrorFrameRule
    from cananalyze.checks.rules.sdo import SdoRule

    found = run_rules([batch], [SdoRule(max_latency_ms=50), ErrorFrameRule(max=1)])
    assert sorted((f.rule, str(f.measured)) for f in found) == [
        ("error_frames", "2"),
        ("sdo", "0x06020000"),
        ("sdo", "80.0"),
    ]


def test_assertions_heartbeat_pdo_rate_signal_and_boot(tmp_path):
    from cananalyze.core.records import SignalBlock

    rules = tmp_path / "rules.yaml"
    rules.write_text(
        "assert:\n"
        "  - heartbeat: {node: 5, period_ms: 100, tolerance: 0.1}\n"
        "  - pdo_rate: {cob_id: 0x285, min_hz: 9, max_hz: 11}\n"
        "  - signal: {node: 5, signal: CH1, min: -50, max: 150}\n"
        "  - operational_after_boot: {node: 3, within_s: 2}\n"
    )
    checker = build_checker(rules)
    dec = Decoder([checker])
    fb = read_all(DEMO)
    # a signal block as the PDO decoder will produce it: CH1 of node 5 on 0x285
    rows_285 = (fb.can_id == 0x285).nonzero()[0]
    values = [100.0] * len(rows_285)
    values[4] = 200.0
    import numpy as np

    class WithSignals:
        def process(self, batch):
            if len(batch):
                batch.signals.append(
                    SignalBlock(rows_285, 5, "tpdo2", 0x285, {"CH1": np.array(values)}, {})
                )

        def finish(self, batch):
            pass

    dec.processors.insert(0, WithSignals())
    dec.decode(fb)
    dec.finish()
    names = {f.rule for f in checker.findings}
    assert "assert_signal" in names
    (sig,) = [f for f in checker.findings if f.rule == "assert_signal"]
    assert sig.measured == 200.0 and sig.t == pytest.approx(fb.t[rows_285[4]])
    assert not {"assert_heartbeat", "assert_pdo_rate", "assert_operational"} & names
    assert_heartbeat(DEMO, node=5, period_ms=100, tolerance=0.05)
    with pytest.raises(AssertionError, match="heartbeat of node 5 every 50 ms"):
        assert_heartbeat(DEMO, node=5, period_ms=50)


@pytest.mark.parametrize(
    "text, where",
    [
        ("rules:\n  heartbeet: {}\n", ":2: unknown rule 'heartbeet'"),
        ("rules:\n  sync:\n    tolerance: lots\n", ":3: tolerance is a fraction"),
        ("assert:\n  - heartbeat: {node: 5}\n", ":2: assert_heartbeat needs 'period_ms'"),
        (
            "network:\n  nodes:\n    5: {heartbeat_ms: -1}\n",
            ":3: network.nodes.5.heartbeat_ms: -1 is out",
        ),
        ("rules: [\n", ":2: not valid YAML"),
        ("x: !!python/object:os.system ls\n", ":1: not valid YAML"),
    ],
)
def test_rules_file_errors_name_the_line(tmp_path, text, where):
    p = tmp_path / "r.yaml"
    p.write_text(text)
    with pytest.raises(InputError, match=f"r.yaml{where}" if where.startswith(":") else where):
        build_checker(p)


def cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )


def test_cli_exit_codes_junit_and_json(tmp_path):
    from junitparser import JUnitXml

    rules = tmp_path / "rules.yaml"
    rules.write_text("rules:\n  emcy: {severity: info}\n  sdo: {severity: info}\n")
    ok = cli(DEMO, "--rules", rules)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    junit, js = tmp_path / "out.xml", tmp_path / "out.json"
    bad = cli(DEMO, "--junit", junit, "--json", js)
    assert bad.returncode == 1
    assert "EMCY 0x8100" in bad.stdout
    suite = next(iter(JUnitXml.fromfile(str(junit))))
    cases = {c.name: c for c in suite}
    assert "heartbeat node 5" in cases and cases["heartbeat node 5"].is_passed
    assert not cases["emcy node 3"].is_passed
    recs = json.loads(js.read_text())
    assert [r["rule"] for r in recs] == ["sdo", "emcy"]
    assert all(r["kind"] == "finding" and r["why"] for r in recs)
    assert cli(tmp_path / "missing.log").returncode == 2
    assert cli(DEMO, "--rules", tmp_path / "nope.yaml").returncode == 2


def test_findings_stream_in_decode_jsonl(tmp_path):
    rows = boot_start([5]) + hb(5, [0.1, 0.2, 0.6, 0.7])
    log = tmp_path / "x.log"
    write_log(from_rows(rows), log)
    rules = tmp_path / "rules.yaml"
    rules.write_text("network:\n  nodes:\n    5: {heartbeat_ms: 100}\n")
    out = cli(log, "--rules", rules, "--json", tmp_path / "f.json")
    assert out.returncode == 1
    (f,) = json.loads((tmp_path / "f.json").read_text())
    assert f["rule"] == "heartbeat" and f["measured"] == pytest.approx(400.0)


def test_real_ixxat_guarding_node9_stops_replying():
    from conftest import real_file

    path = real_file("hilch__canopen-message-interpreter/ixxat1.trc")
    found = run_rules(path, build_checker().rules)
    no_reply = [
        f for f in found if f.rule == "guarding" and f.node == 9 and "no reply" in f.message
    ]
    # node 9 answers every request until 00:02:47.31, then only requests follow
    assert no_reply
    import datetime

    start = datetime.datetime(2025, 1, 28, 10, 47, 15).timestamp()  # the first row, 140.66 s
    assert min(f.t for f in no_reply) == pytest.approx(start + 170.31 - 140.66, abs=0.01)
    # pcan2 starts mid-session: its first guard reply's toggle is not a violation
    pcan2 = run_rules(
        real_file("hilch__canopen-message-interpreter/pcan2.trc"), build_checker().rules
    )
    assert not [f for f in pcan2 if "toggle" in f.message]


def test_real_tmcm_rpdo4_length_matches_its_mapping(tmp_path):
    from conftest import real_file

    log = real_file("nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt")
    dcf = real_file("nigel-bruce-khan__ros_canopen-tmcm-1636/TMCM-1636-CANopen.dcf")
    net = tmp_path / "net.yaml"
    net.write_text(f"nodes:\n  1: {{eds: {dcf}}}\n")
    found = run_rules(log, build_checker().rules, network=net)
    # 0x1603 maps one 8-bit object (0x6060): the 1-byte RPDO4 on 0x501 is right
    assert not [f for f in found if f.rule == "pdo_length"]
    assert [f.measured for f in found if f.rule == "emcy"] == ["0x6320"]
