"""`cananalyze decode` end to end through the CLI: output, filters, summary, errors, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys

from conftest import ROOT, real_file

DEMO = str(ROOT / "samples" / "demo.log")


def cli(*args: str, stdin: bytes | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, cwd=ROOT, input=stdin
    )


def test_text_output_names_every_service():
    out = cli("decode", DEMO, "--no-color")
    assert out.returncode == 0, out.stderr
    text = out.stdout.decode()
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("└─")]
    assert len(lines) == 185
    assert "\x1b[" not in text
    for expected in (
        "bootup           3  boot-up",
        "NMT start all nodes",
        "TIME 2026-01-01T00:00:00.100Z",
        "SYNC counter 1",
        "heartbeat operational",
        "node guarding request (RTR)",
        "node guarding response operational toggle 1",
        "EMCY 0x8100 Communication; register 0x01 [generic]; mfr 0000000040",
        "EMCY error reset / no error",
        "0x06020000 Object does not exist in the object dictionary",
        "node 5 SDO read 0x1008:00 Manufacturer device name segmented -> ok",
    ):
        assert expected in text, expected


def test_jsonl_schema():
    out = cli("decode", DEMO, "--format", "jsonl")
    recs = [json.loads(line) for line in out.stdout.splitlines()]
    frames = [r for r in recs if r["kind"] == "frame"]
    assert len(frames) == 185
    for r in frames:
        assert {"t", "channel", "can_id", "dlc", "data", "service", "node"} <= r.keys()
    by_service = {}
    for r in frames:
        by_service.setdefault(r["service"], r)
    assert by_service["nmt"]["command"] == "start" and by_service["nmt"]["target"] == 0
    assert by_service["sync"]["counter"] == 1
    assert by_service["emcy"]["error_code"] == 0x8100 and by_service["emcy"]["reset"] is False
    assert by_service["heartbeat"]["state"] == "operational"
    assert by_service["guard_request"]["rtr"] is True
    assert by_service["guard_response"]["toggle"] == 0
    assert by_service["tpdo"]["pdo"] in (1, 2)
    assert by_service["sdo_request"]["index"] == 0x1018
    abort = [r for r in frames if r.get("abort_code")]
    assert abort[0]["abort_code"] == 0x06020000
    assert abort[0]["abort_text"] == "Object does not exist in the object dictionary"
    sdo = [r for r in recs if r["kind"] == "sdo"]
    assert [r["result"] for r in sdo].count("ok") == 6 and len(sdo) == 7


def test_filters_and_summary():
    out = cli("decode", DEMO, "--node", "5", "--service", "heartbeat", "--no-color")
    lines = out.stdout.decode().splitlines()
    assert len(lines) == 20 and all("heartbeat" in ln and "705" in ln for ln in lines)
    out = cli("decode", DEMO, "--from", "1.0", "--to", "1.2", "--service", "sync", "--no-color")
    assert len(out.stdout.decode().splitlines()) == 2
    out = cli("decode", DEMO, "--summary", "--bitrate", "250000")
    text = out.stdout.decode()
    assert "frames: 185" in text and "duration: 2.020300 s" in text
    assert "bus load:" in text and "node   5:" in text
    assert "node 3: 2 (abort 1, ok 1)" in text
    # how each node was identified
    assert (
        "node   5: Datexel DAT 7014" in text and "(identified by SDO 0x1018 vendor/product)" in text
    )
    assert "node  10: unknown device" in text
    out = cli("decode", DEMO, "--summary", "--device", "3=mcb560")
    assert (
        "node   3: ANDIG MCB-560" in out.stdout.decode()
        and "(identified by user --device)" in out.stdout.decode()
    )


def test_sdo_table_only():
    out = cli("decode", DEMO, "--sdo")
    lines = out.stdout.decode().splitlines()
    assert len(lines) == 7 and all(" SDO " in ln for ln in lines)


def test_sdo_values_named_and_decoded():
    out = cli("decode", DEMO, "--sdo")
    text = out.stdout.decode()
    assert (
        "node 5 SDO read 0x1018:01 Identity object: Vendor-ID expedited -> ok: 973 (0x3CD)" in text
    )
    assert "0x1008:00 Manufacturer device name segmented -> ok: 'DAT7014'" in text
    assert "0x1017:00 Producer heartbeat time expedited -> ok: 100 (0x64)" in text
    recs = [
        json.loads(x) for x in cli("decode", DEMO, "--sdo", "--format", "jsonl").stdout.splitlines()
    ]
    assert [r["value"] for r in recs[:4]] == [0x3CD, 2, 0x40191, "DAT7014"]
    assert recs[0]["name"] == "Identity object: Vendor-ID"


def test_bad_input_is_one_line_never_a_traceback(tmp_path):
    bad = tmp_path / "bad.log"
    bad.write_text("(1.0) can0 181#0102\n(2.0) can0 181#XYZ\n(3.0) can0 181#03\n")
    out = cli("decode", str(bad))
    assert out.returncode == 0
    err = out.stderr.decode()
    assert "bad.log:line 2:" in err and "1 unreadable lines/records skipped" in err
    assert len(out.stdout.decode().splitlines()) == 2
    out = cli("decode", str(bad), "--strict")
    assert out.returncode == 2
    err = out.stderr.decode()
    assert "Traceback" not in err and "bad.log:line 2: invalid hex" in err
    assert "181" in out.stdout.decode()  # the frame decoded before the problem was not lost
    for args, needle in (
        (("decode", str(tmp_path / "missing.log")), "no such file"),
        (("decode", str(tmp_path)), "is a directory"),
        (("decode", DEMO, "--service", "bogus"), "unknown service"),
        (("decode", DEMO, "--node", "x"), "--node takes node-IDs"),
    ):
        out = cli(*args)
        assert (
            out.returncode == 2 and needle in out.stderr.decode() and b"Traceback" not in out.stderr
        )
    empty = tmp_path / "empty.log"
    empty.write_bytes(b"")
    out = cli("decode", str(empty))
    assert out.returncode == 2 and "empty" in out.stderr.decode()


def test_eds_given_as_log_is_refused_with_what_it_is():
    out = cli("decode", str(real_file("christiansandberg__canopen/sample.eds")))
    assert out.returncode == 2
    assert "EDS/DCF device description" in out.stderr.decode()


def test_non_canopen_log_is_labelled():
    out = cli("decode", str(real_file("hardbyte__python-can/issue_1256.asc")), "--summary")
    assert out.returncode == 0
    assert (
        "not look like CANopen" in out.stdout.decode()
        or "may not be CANopen" in out.stdout.decode()
    )


def test_decode_with_rules_streams_the_same_findings_as_check(tmp_path):
    samples = ROOT / "samples"
    common = ["--rules", str(samples / "rules.yaml"), "--network", str(samples / "network.toml")]
    out = cli("decode", str(samples / "faults.log"), "--format", "jsonl", *common)
    assert out.returncode == 0, out.stderr
    recs = [json.loads(x) for x in out.stdout.splitlines()]
    findings = [(r["rule"], r["node"], round(r["t"], 6)) for r in recs if r["kind"] == "finding"]
    js = tmp_path / "f.json"
    assert cli("check", str(samples / "faults.log"), *common, "--json", str(js)).returncode == 1
    expected = [(r["rule"], r["node"], round(r["t"], 6)) for r in json.loads(js.read_text())]
    assert sorted(findings, key=str) == sorted(expected, key=str) and len(findings) == 16
    # a finding follows the frame that raised it in the text output
    text = (
        cli(
            "decode",
            str(samples / "faults.log"),
            "--check",
            "--no-color",
            "--network",
            str(samples / "network.toml"),
        )
        .stdout.decode()
        .splitlines()
    )
    i = next(i for i, ln in enumerate(text) if "└─ WARNING emcy: EMCY 0x8100" in ln)
    assert "EMCY 0x8100" in text[i - 1] and " 083 " in text[i - 1]
