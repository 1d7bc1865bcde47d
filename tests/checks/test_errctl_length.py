"""Error-control frames of the wrong length (CiA 301: heartbeat, boot-up and guard response
are exactly 1 byte): `errctl_invalid`, no node's state, one `errctl_length` per COB-ID.

SavvyCAN's car logs carry 8-byte frames on 0x708/0x718/0x74A/0x754: read as boot-ups and
heartbeats they gave ~1100 false `unexpected_bootup`/`pdo_not_operational` findings.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from collections import Counter

import can
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, real_file

import cananalyze
from cananalyze.core.frames import FLAG_RTR, from_rows
from cananalyze.fleet import schema as fleet_schema
from cananalyze.formats.logfile import write_log
from cananalyze.formats.source import read_all
from cananalyze.outputs.tables.stream import TableSink
from cananalyze.pipeline import Options, build_decoder, open_source, run
from cananalyze.protocol.cobid import CobClassifier
from cananalyze.protocol.services import SERVICE_NAMES, Service, parse_services

CANDUMP = "collin80__SavvyCAN/candump.log"
GVRET = "collin80__SavvyCAN/GVRET_Log.csv"
MALFORMED_8 = "malformed: 8 data bytes, CiA 301 says 1"


def _is_bad(can_id: int, ext: bool, rtr: bool, dlc: int) -> bool:
    return not ext and not rtr and 0x701 <= can_id <= 0x77F and dlc != 1


def _bad_per_cob_candump(path) -> Counter:
    """python-can's reading of the candump log: non-RTR 0x701-0x77F frames not 1 byte."""
    with can.CanutilsLogReader(str(path)) as reader:
        return Counter(
            m.arbitration_id
            for m in reader
            if _is_bad(m.arbitration_id, m.is_extended_id, m.is_remote_frame, m.dlc)
        )


def _bad_per_cob_gvret(path) -> Counter:
    """A plain csv reading of the GVRET log (ID in hex, Extended, LEN)."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return Counter(
        int(r["ID"], 16)
        for r in rows
        if _is_bad(int(r["ID"], 16), r["Extended"].strip().lower() == "true", False, int(r["LEN"]))
    )


@pytest.mark.parametrize(
    "rel, independent", [(CANDUMP, _bad_per_cob_candump), (GVRET, _bad_per_cob_gvret)]
)
def test_savvycan_car_traffic_is_no_error_control(rel, independent):
    path = real_file(rel)
    want = independent(path)
    assert {0x708, 0x718, 0x74A, 0x754} <= set(want)  # the car's 8-byte frames, and more
    found = cananalyze.check(path)
    rules = Counter(f.rule for f in found)
    # were 44 unexpected_bootup and ~1000 pdo_not_operational (1136 / 1067 in all)
    assert rules["unexpected_bootup"] == rules["pdo_not_operational"] == 0
    assert rules["heartbeat"] == 0
    errctl = [f for f in found if f.rule == "errctl_length"]
    assert {f.cob_id: f.message.split(" ")[0] for f in errctl} == {
        cob: str(n) for cob, n in want.items()
    }
    for f in errctl:
        assert f.severity == "warning" and f.node == f.cob_id - 0x700
        assert f.message == (
            f"{want[f.cob_id]} frames on 0x{f.cob_id:03X} with 8 data bytes; "
            "error control (heartbeat/boot-up/guarding) is 1 byte"
        )
        assert (f.measured, f.expected) == (8, 1)
    assert len(found) == rules["errctl_length"] + rules["unknown_cob_id"] + rules["sdo"] < 50
    # no node got a state from these frames
    cap = cananalyze.load(path)
    assert not (cap.events["kind"] == "nmt_state").any()
    assert not (cap.events["kind"] == "bootup").any()
    nodes = cap.nodes  # indexed by node
    for cob, n in want.items():
        assert nodes.loc[cob - 0x700, "frames_errctl_invalid"] == n
    assert nodes["last_state"].isna().all()


def _interleaved() -> list[tuple[float, int, bytes]]:
    """Node 5 beats operational every 100 ms (a boot-up first); 8-byte frames on 0x705
    between, starting 0x00 (a boot-up's byte) or 0x04 (stopped's)."""
    rows = [(0.0, 0x705, b"\x00")]
    rows += [(0.1 * k, 0x705, b"\x05") for k in range(1, 31)]
    rows += [
        (0.1 * k + 0.05, 0x705, bytes([0x00 if k % 2 else 0x04]) + bytes(7)) for k in range(30)
    ]
    rows += [(0.1 * k + 0.02, 0x185, bytes(8)) for k in range(1, 31)]  # TPDO1 of node 5
    return sorted(rows)


def test_wrong_length_frames_leave_node_state_and_heartbeat_alone(tmp_path):
    log = tmp_path / "hb.log"
    rows = _interleaved()
    write_log(from_rows(rows), log)
    cap = cananalyze.load(log)
    states = cap.events[cap.events["kind"] == "nmt_state"]
    assert states["message"].tolist() == [
        "node 5: NMT state pre-operational",  # after its boot-up (CiA 301 7.3.2.2)
        "node 5: NMT state operational",
    ]
    assert (cap.events["kind"] == "bootup").sum() == 1
    hb = cap.heartbeat(5)  # the 1-byte frames only: 30 of them, 100 ms apart
    assert hb["count"] == 29 and hb["min"] == hb["max"] == 100.0
    (node,) = cap.nodes.to_dict("records")
    assert node["frames_heartbeat"] == 30 and node["frames_bootup"] == 1
    assert node["frames_errctl_invalid"] == 30 and node["last_state"] == "operational"
    found = cananalyze.check(log)
    assert [(f.rule, f.cob_id, f.node) for f in found] == [("errctl_length", 0x705, 5)]
    (f,) = found
    assert f.t == pytest.approx(0.05)
    assert f.message.startswith("30 frames on 0x705 with 8 data bytes")


def _guarded() -> list[tuple[float, int, bytes, int]]:
    """A guard request (RTR) on 0x705, an 8-byte frame on 0x705, then the 1-byte answer."""
    out = []
    for k in range(6):
        t = 0.5 * k
        out += [(t, 0x705, b"", FLAG_RTR), (t + 0.001, 0x705, bytes(8), 0)]
        out += [(t + 0.002, 0x705, bytes([0x05 | (0x80 if k % 2 else 0)]), 0)]
    return out


def _guard_batch():
    rows = _guarded()
    fb = from_rows([(t, i, d) for t, i, d, _ in rows])
    fb.flags[:] |= np.array([fl for *_, fl in rows], np.uint8)
    fb.dlc[0::3] = 1  # the request asks for 1 byte
    return fb


def test_guard_request_still_pairs_across_a_wrong_length_frame(tmp_path):
    fb = _guard_batch()
    want = [Service.GUARD_REQUEST, Service.ERRCTL_INVALID, Service.GUARD_RESPONSE] * 6
    for classify in (CobClassifier().classify, CobClassifier()._classify_numpy):
        assert classify(fb).service.tolist() == want
    # cut between the request and the answer: the state crosses batches too
    for classify in ("classify", "_classify_numpy"):
        c = CobClassifier()
        got = np.concatenate(
            [getattr(c, classify)(fb.take(np.arange(a, b))).service for a, b in ((0, 2), (2, 18))]
        )
        assert got.tolist() == want
    log = tmp_path / "guard.log"
    write_log(fb, log)
    cap = cananalyze.load(log)
    assert (cap.frames["service"] == "guard_response").sum() == 6
    rules = Counter(f.rule for f in cananalyze.check(log))
    assert rules == {"errctl_length": 1}  # no missing reply, no toggle error


def test_decode_text_and_jsonl_say_malformed(tmp_path):
    log = tmp_path / "hb.log"
    write_log(from_rows(_interleaved()[:8]), log)
    env_run = [sys.executable, "-m", "cananalyze", "decode", str(log)]
    text = subprocess.run(env_run, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    bad = [ln for ln in text.splitlines() if "errctl_invalid" in ln]
    assert bad and all(ln.endswith(f"error control ({MALFORMED_8})") for ln in bad)
    out = subprocess.run(
        [*env_run, "--format", "jsonl"], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout
    recs = [json.loads(ln) for ln in out.splitlines()]
    invalid = [r for r in recs if r.get("service") == "errctl_invalid"]
    assert len(invalid) == len(bad) > 0
    assert all(r["problem"] == MALFORMED_8 and "state" not in r for r in invalid)
    assert all(r["dlc"] == 8 and r["node"] == 5 for r in invalid)


def test_rule_can_be_disabled(tmp_path):
    log = tmp_path / "hb.log"
    write_log(from_rows(_interleaved()), log)
    rules = tmp_path / "rules.yaml"
    rules.write_text("rules:\n  errctl_length: false\n")
    assert cananalyze.check(log, rules=rules) == []
    rules.write_text("rules:\n  errctl_length: {severity: error}\n")
    (f,) = cananalyze.check(log, rules=rules)
    assert (f.rule, f.severity) == ("errctl_length", "error")


def test_one_finding_per_cob_id_and_bus(tmp_path):
    log = tmp_path / "two.log"
    log.write_text(
        "(0.000000) can0 708#0102030405060708\n"
        "(0.100000) can1 708#01020304\n"
        "(0.200000) can0 708#0102030405060708\n"
        "(0.300000) can1 708#01\n"
        "(0.400000) can1 708#0102\n"
        "(0.500000) can0 70A#\n"
    )
    got = sorted((f.bus, f.cob_id, f.message.split(";")[0], f.t) for f in cananalyze.check(log))
    assert got == [
        ("can0", 0x708, "2 frames on 0x708 with 8 data bytes", 0.0),
        ("can0", 0x70A, "1 frame on 0x70A with 0 data bytes", 0.5),
        ("can1", 0x708, "2 frames on 0x708 with 2-4 data bytes", 0.1),
    ]


def test_service_name_tables_and_fleet_schema(tmp_path):
    assert SERVICE_NAMES[Service.ERRCTL_INVALID] == "errctl_invalid" == Service(16).label
    assert Service.ERRCTL_INVALID in parse_services("errctl")
    assert parse_services("errctl_invalid") == {Service.ERRCTL_INVALID}
    nodes = fleet_schema.schema("nodes")
    assert nodes.field("frames_errctl_invalid").type == "int64"
    log = real_file(CANDUMP)
    out = tmp_path / "pq"
    opts = Options(checks=True)
    run(open_source(log, opts), build_decoder(opts), [TableSink(out, "parquet")], opts)
    frames = pq.read_table(out / "frames.parquet")
    svc = frames.column("service").combine_chunks()
    assert "errctl_invalid" in svc.dictionary.to_pylist()
    names = svc.cast(pa.string()).to_pylist()
    fb = read_all(log)
    ec = (fb.can_id >= 0x701) & (fb.can_id <= 0x77F) & (fb.dlc != 1)
    assert names.count("errctl_invalid") == int(ec.sum()) > 0
    table = pq.read_table(out / "nodes.parquet")
    counts = table["frames_errctl_invalid"].to_pylist()
    assert sum(c for c in counts if c) == int(ec.sum())
    conformed = fleet_schema.conform(table, "nodes", {"source": "x", "hash": "h", "version": "v"})
    assert conformed.schema.remove_metadata().equals(nodes)


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan1.trc",
        "hilch__canopen-message-interpreter/pcan2.trc",
        "hilch__canopen-message-interpreter/pcan3.trc",
        "hilch__canopen-message-interpreter/ixxat1.trc",
        "isPointless__Sevcon/can_230309_150427.txt",
        "jclinton830__canopen_test/candump.txt",
        "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
        "RoboTrainerAID__za_experimental/candump.log",
        "collin80__SavvyCAN/CarBusAnalyzer.trc",
    ],
)
def test_canopen_logs_have_no_wrong_length_error_control(rel):
    """The real CANopen logs' error control is all 1 byte: nothing reclassified there."""
    cap = cananalyze.load(real_file(rel))
    assert not (cap.frames["service"] == "errctl_invalid").any()
    assert not (cap.findings["rule"] == "errctl_length").any() if len(cap.findings) else True


def test_each_length_its_own_text_in_one_batch(tmp_path):
    """The columnar writers group rows by what their text says: here, the length."""
    log = tmp_path / "lengths.log"
    lengths = [8, 2, 0, 8, 3, 2, 7]
    write_log(from_rows([(0.1 * i, 0x705, bytes(n)) for i, n in enumerate(lengths)]), log)
    cap = cananalyze.load(log)
    assert (cap.frames["service"] == "errctl_invalid").all()
    cmd = [sys.executable, "-m", "cananalyze", "decode", str(log)]
    text = subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    said = [ln.split("error control (malformed: ")[1].split(" ")[0] for ln in text.splitlines()]
    assert said == [str(n) for n in lengths]
    out = subprocess.run(
        [*cmd, "--format", "jsonl"], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout
    problems = [json.loads(ln)["problem"] for ln in out.splitlines()]
    assert problems == [f"malformed: {n} data bytes, CiA 301 says 1" for n in lengths]
