"""A device named by a read in the log names that node's later transfers of the same batch.

The master here is python-canopen reading a CiA 402 drive's device type (0x1000) and then
its statusword, writing its mode of operation and a TPDO mapping entry: no --device, no
EDS, one batch. Every transfer after the 0x1000 read is named by the CiA 402 profile it
gave, in load(), the text output and JSONL; on the tracker route and the fast path alike.
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys

import can
import canopen
import pytest

import cananalyze
from tests.conftest import real_file
from tests.helpers.virtual_bus import drain, patient_client, unique_channel

SLAVE_EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"


def _record(tmp_path, reads_before: int = 0) -> str:
    """candump of: [reads of 0x6041 before], 0x1000 read, 0x6041 read, 0x6060 write,
    0x1A00:01 write (a mapping entry: words name the mapped object)."""
    logging.getLogger("canopen").setLevel(logging.ERROR)
    channel = unique_channel("identify")
    recorder = can.Bus(interface="virtual", channel=channel)
    server_net, client_net = canopen.Network(), canopen.Network()
    server_net.connect(interface="virtual", channel=channel)
    client_net.connect(interface="virtual", channel=channel)
    try:
        drive = canopen.LocalNode(5, str(real_file(SLAVE_EDS)))
        server_net.add_node(drive)
        drive.sdo[0x6041].raw = 0x0237
        master = patient_client(5)
        client_net.add_node(master)
        for _ in range(reads_before):
            master.sdo.upload(0x6041, 0)
        assert int.from_bytes(master.sdo.upload(0x1000, 0), "little") == 0x00060192
        assert master.sdo.upload(0x6041, 0) == b"\x37\x02"
        master.sdo.download(0x6060, 0, b"\x01")
        master.sdo.download(0x1A00, 1, (0x60410010).to_bytes(4, "little"))
        frames = drain(recorder)
    finally:
        server_net.disconnect()
        client_net.disconnect()
        recorder.shutdown()
    path = tmp_path / "identify.log"
    with open(path, "w") as f:
        for m in frames:
            f.write(f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#{m.data.hex().upper()}\n")
    return str(path)


@pytest.mark.parametrize("pure", [False, True], ids=["fast", "tracker"])
def test_transfers_after_the_device_type_read_are_named(tmp_path, monkeypatch, pure):
    log = _record(tmp_path, reads_before=2)
    if pure:
        monkeypatch.setenv("CANANALYZE_PURE", "1")
    cap = cananalyze.load(log)
    assert cap.profiles[5][0] == "cia402"
    sdo = cap.sdo.set_index(["index", "subindex"])
    *before, after = sdo.loc[(0x6041, 0)]["name"].tolist()
    assert len(before) == 2 and sdo.loc[(0x6041, 0)]["name"].isna().tolist() == [True, True, False]
    assert after == "Statusword"  # read after the device type: named, as an EDS names it
    assert sdo.loc[(0x6041, 0)]["value"].tolist()[2] == 0x0237
    assert set(sdo.loc[[(0x6060, 0)], "name"]) == {"Modes of operation"}
    assert set(sdo.loc[[(0x1A00, 1)], "words"]) == {"6041:00, 16 bit, Statusword"}


def test_text_and_jsonl_name_them_too(tmp_path):
    log = _record(tmp_path)
    run = [sys.executable, "-m", "cananalyze", "decode", log]
    text = subprocess.run(run, capture_output=True, text=True, check=True).stdout
    assert "SDO read 0x6041:00 Statusword expedited -> ok: 567 (0x237) (operation enabled" in text
    lines = subprocess.run(
        [*run, "--format", "jsonl"], capture_output=True, text=True, check=True
    ).stdout
    recs = [json.loads(x) for x in lines.splitlines()]
    named = {(r["index"], r["subindex"]): r["name"] for r in recs if r.get("kind") == "sdo"}
    assert named[(0x1000, 0)] == "Device type" and named[(0x6041, 0)] == "Statusword"


def test_tables_and_mcap_name_them_too(tmp_path):
    """The Parquet sdo table (pyarrow) and the MCAP events (the mcap library's reader)
    name the transfers after the 0x1000 read as the drive's EDS would."""
    import pyarrow.parquet as pq
    from mcap.reader import make_reader

    log = _record(tmp_path)
    out = tmp_path / "out"
    subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", log]
        + ["--parquet", str(out), "--mcap", str(tmp_path / "x.mcap"), "-q"],
        check=True,
        timeout=120,
    )
    sdo = pq.read_table(out / "sdo.parquet").to_pylist()
    names = {(r["index"], r["subindex"]): r["name"] for r in sdo}
    assert names[(0x6041, 0)] == "Statusword" and names[(0x6060, 0)] == "Modes of operation"
    with open(tmp_path / "x.mcap", "rb") as f:
        texts = [
            json.loads(m.data)["message"]
            for _, _, m in make_reader(f).iter_messages(topics=["/canopen/events"])
        ]
    assert any(t.startswith("SDO upload 0x6041:00 Statusword = 567") for t in texts)
    assert any(t.startswith("SDO download 0x6060:00 Modes of operation = 1") for t in texts)
