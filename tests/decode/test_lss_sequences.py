"""LSS (CiA 305) sequences from python-canopen's LssMaster: a fastscan finds the one
non-configured slave, which gets node-ID 5 and stores it; a selective switch to an
identity nobody has goes unanswered; the slave refuses node-ID 200; a second fastscan
finds no non-configured slave. load(), the `lss` rule and `decode --summary` tell it.
"""

from __future__ import annotations

import logging
import subprocess
import sys

import can
import canopen
import pytest
from canopen.lss import LssError

import cananalyze
from tests.helpers.lss_slave import LssSlave
from tests.helpers.virtual_bus import drain, unique_channel

IDENTITY = (0x0000004C, 0x00000001, 0x00010000, 0x00000005)  # few 1-bits: few timeouts
NOBODY = (0x0000004C, 0x00000001, 0x00010000, 0x00000006)


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    logging.getLogger("canopen").setLevel(logging.ERROR)
    channel = unique_channel("lss")
    recorder = can.Bus(interface="virtual", channel=channel)
    slave_bus = can.Bus(interface="virtual", channel=channel)
    notifier = can.Notifier(slave_bus, [LssSlave(slave_bus, IDENTITY)])
    net = canopen.Network()
    net.connect(interface="virtual", channel=channel)
    try:
        lss = net.lss
        lss.RESPONSE_TIMEOUT = 0.5  # an unanswered probe costs this; answers come in us
        lss.send_switch_state_global(lss.WAITING_STATE)
        found, ident = lss.fast_scan()
        assert found and tuple(ident) == IDENTITY
        lss.configure_node_id(5)
        lss.store_configuration()
        lss.send_switch_state_global(lss.WAITING_STATE)
        with pytest.raises(LssError):
            lss.send_switch_state_selective(*NOBODY)
        lss.send_switch_state_selective(*IDENTITY)
        with pytest.raises(LssError):
            lss.configure_node_id(200)  # out of range: error 1
        lss.send_switch_state_global(lss.WAITING_STATE)
        found, _ = lss.fast_scan()
        assert not found  # node-ID 5 now: no non-configured slave
        frames = drain(recorder)
    finally:
        net.disconnect()
        notifier.stop()
        slave_bus.shutdown()
        recorder.shutdown()
    path = tmp_path_factory.mktemp("lss") / "lss.log"
    with can.CanutilsLogWriter(str(path), channel="vcan0") as w:
        for m in frames:
            w.on_message_received(m)
    return path


def test_who_got_which_node_id(log):
    got = cananalyze.load(log).lss_assignments.to_dict("records")
    assert len(got) == 1
    a = got[0]
    assert (a["vendor_id"], a["product_code"], a["revision"], a["serial"]) == IDENTITY
    assert (a["node_id"], a["stored"]) == (5, True)


def test_each_step_with_its_result(log):
    steps = cananalyze.load(log).lss[["step", "result", "node_id"]].values.tolist()
    steps = [[s, r, None if n != n else n] for s, r, n in steps]  # NaN: no node-ID
    assert steps == [
        ["switch state global", "sent", None],
        ["fastscan", "found", None],
        ["configure node-ID", "ok", 5],
        ["store configuration", "ok", None],
        ["switch state global", "sent", None],
        ["switch state selective", "no answer", None],
        ["switch state selective", "selected", None],
        ["configure node-ID", "error 1: node-ID out of range", 200],
        ["switch state global", "sent", None],
        ["fastscan", "no non-configured slave", None],
    ]
    scan = cananalyze.load(log).lss.iloc[1]
    assert (scan.vendor_id, scan.product_code, scan.revision, scan.serial) == IDENTITY


def test_the_failures_are_findings_and_the_empty_scan_is_not(log):
    f = cananalyze.load(log).findings
    lss = f[f["rule"] == "lss"]
    assert lss["severity"].tolist() == ["warning", "error"]
    assert "no slave answered (vendor 0x0000004C" in lss["message"].iloc[0]
    assert (
        "configure node-ID node-ID 200: error 1: node-ID out of range" in (lss["message"].iloc[1])
    )
    assert "selected: vendor 0x0000004C, product 0x00000001" in lss["message"].iloc[1]


def test_summary_lists_the_assignment(log):
    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--summary"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert (
        "LSS: node-ID 5 given to vendor 0x0000004C, product 0x00000001, revision "
        "0x00010000, serial 0x00000005 (stored)" in run.stdout
    )


def test_summary_json_has_the_assignment(log):
    import json

    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--summary", "--format", "jsonl"],
        capture_output=True,
        text=True,
        check=True,
    )
    rec = json.loads(run.stdout.splitlines()[-1])
    [a] = rec["lss_assignments"]
    assert (a["vendor_id"], a["serial"], a["node_id"], a["stored"]) == (0x4C, 5, 5, True)
    assert rec["verdict"] is None  # LSS traffic is CANopen
