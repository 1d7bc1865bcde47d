"""SdoTracker against real traffic of the `canopen` package on python-can's virtual bus.

canopen's SDO client talks to canopen's own server (LocalNode) for expedited and
segmented transfers, and to tests/helpers/sdo_block_server.py for block ones
(canopen has no block server). A third bus instance records the bus as a
passive analyser would; every transaction the tracker rebuilds must match what
the client asked for and got.
"""

from __future__ import annotations

import struct

import can
import canopen
import pytest
from canopen.objectdictionary import DOMAIN, INTEGER16, REAL32, UNSIGNED32, VISIBLE_STRING
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from cananalyze.decode.sdo import SdoTracker
from tests.helpers.sdo_block_server import BlockSdoServer
from tests.helpers.virtual_bus import (
    drain,
    od_info,
    patient_client,
    track,
    unique_channel,
    variable,
)

NODE = 5
NAME = b"cananalyze test device, segmented"


def _od() -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()
    od.add_object(
        variable(0x1008, 0, "Manufacturer device name", VISIBLE_STRING, "ro", NAME.decode())
    )
    od.add_object(variable(0x2000, 0, "Counter", UNSIGNED32, "rw", 0x12345678))
    od.add_object(variable(0x2001, 0, "Offset", INTEGER16, "rw", -300))
    od.add_object(variable(0x2002, 0, "Gain", REAL32, "rw", 1.5))
    od.add_object(variable(0x2003, 0, "Blob", DOMAIN, "rw", b""))
    return od


@pytest.fixture
def bus():
    channel = unique_channel("sdo")
    od = _od()
    server_net, client_net = canopen.Network(), canopen.Network()
    server_net.connect(interface="virtual", channel=channel)
    client_net.connect(interface="virtual", channel=channel)
    recorder = can.Bus(interface="virtual", channel=channel)
    local = server_net.create_node(NODE, od) if hasattr(server_net, "create_node") else None
    if local is None:
        local = canopen.LocalNode(NODE, od)
        server_net.add_node(local)
    remote = patient_client(NODE, _od())
    client_net.add_node(remote)
    yield client_net, remote, recorder, od
    recorder.shutdown()
    client_net.disconnect()
    server_net.disconnect()


@pytest.mark.slow
def test_expedited_segmented_reads_writes_abort(bus) -> None:
    client_net, remote, recorder, od = bus
    sdo = remote.sdo
    expected = []  # (direction, protocol, index, result, data or abort code)

    expected.append(("upload", "expedited", 0x2000, "ok", sdo.upload(0x2000, 0)))
    expected.append(("upload", "segmented", 0x1008, "ok", sdo.upload(0x1008, 0)))
    sdo.download(0x2001, 0, struct.pack("<h", -1234))
    expected.append(("download", "expedited", 0x2001, "ok", struct.pack("<h", -1234)))
    sdo.download(0x2002, 0, struct.pack("<f", -2.25))
    expected.append(("download", "expedited", 0x2002, "ok", struct.pack("<f", -2.25)))
    blob = bytes(range(40))
    sdo.download(0x2003, 0, blob)  # > 4 bytes: segmented with size
    expected.append(("download", "segmented", 0x2003, "ok", blob))
    sdo.download(0x2000, 0, b"\x01\x02\x03\x04", force_segment=True)
    expected.append(("download", "segmented", 0x2000, "ok", b"\x01\x02\x03\x04"))
    expected.append(("upload", "segmented", 0x2003, "ok", sdo.upload(0x2003, 0)))
    with pytest.raises(SdoAbortedError) as aborted:
        sdo.upload(0x3000, 0)
    expected.append(("upload", None, 0x3000, "abort", aborted.value.code))

    tracker = SdoTracker(object_info=od_info(od))
    transactions = track(drain(recorder), tracker)
    assert len(transactions) == len(expected)
    for tx, (direction, protocol, index, result, got) in zip(transactions, expected, strict=True):
        assert (tx.direction, tx.protocol, tx.index, tx.subindex, tx.result) == (
            direction,
            protocol,
            index,
            0,
            result,
        ), tx
        assert tx.node == NODE and tx.channel == (0x600 + NODE, 0x580 + NODE)
        if result == "ok":
            assert bytes.fromhex(tx.data) == got and tx.size == len(got) and tx.detail is None
        else:
            assert tx.abort_code == got == 0x06020000
    by_index = {tx.index: tx for tx in transactions if tx.result == "ok"}
    assert transactions[1].value == NAME.decode()
    assert transactions[2].value == -1234 and transactions[2].name == "Offset"
    assert transactions[3].value == -2.25
    assert transactions[4].value == blob.hex()
    assert by_index[0x2000].value == 0x04030201
    assert all(tx.latency_ms is not None and tx.latency_ms >= 0 for tx in transactions)


def test_missing_node_times_out(bus) -> None:
    client_net, remote, recorder, od = bus
    ghost = canopen.RemoteNode(42, _od())
    client_net.add_node(ghost)
    ghost.sdo.RESPONSE_TIMEOUT = 0.05
    with pytest.raises(SdoCommunicationError):
        ghost.sdo.upload(0x1000, 0)
    frames = drain(recorder)
    # canopen gives up with an abort 0x05040000 (index 0:0) after its own timeout.
    assert [f.data[0] for f in frames] == [0x40, 0x80]

    # An analyser whose timeout is shorter than the client's sees a timeout first, and
    # the client's late abort is then attached as a frame role, not a second transaction.
    (tx,) = track(frames, SdoTracker(timeout=0.01))
    assert (tx.result, tx.node, tx.index, tx.direction) == ("timeout", 42, 0x1000, "upload")
    assert tx.latency_ms is None and "no frame within" in tx.detail

    # With a longer one, what ends the transfer is the client's abort.
    (tx,) = track(frames, SdoTracker(timeout=1.0))
    assert (tx.result, tx.abort_code, tx.index) == ("abort", 0x05040000, 0x1000)
    assert "aborted by client" in tx.detail


@pytest.mark.parametrize("crc", [True, False])
@pytest.mark.parametrize("blksizes", [(127,), (4, 7, 2)])
@pytest.mark.slow
def test_block_transfers_with_canopen_client(crc: bool, blksizes: tuple[int, ...]) -> None:
    channel = unique_channel("block")
    big = bytes((i * 7 + 3) & 0xFF for i in range(1000))  # > 127 * 7: two upload sub-blocks
    objects = {(0x2100, 0): big, (0x2101, 0): b"short", (0x2102, 0): b"\x2a\x00"}
    server_bus = can.Bus(interface="virtual", channel=channel)
    server = BlockSdoServer(server_bus, NODE, objects, blksizes=blksizes, crc=crc)
    notifier = can.Notifier(server_bus, [server])
    recorder = can.Bus(interface="virtual", channel=channel)
    net = canopen.Network()
    net.connect(interface="virtual", channel=channel)
    remote = patient_client(NODE)
    net.add_node(remote)
    try:
        with remote.sdo.open(0x2100, 0, "rb", block_transfer=True, request_crc_support=crc) as f:
            read_big = f.read()
        payload = bytes(range(256)) * 2 + b"tail"
        with remote.sdo.open(
            0x2200, 0, "wb", size=len(payload), block_transfer=True, request_crc_support=crc
        ) as f:
            f.write(payload)
    finally:
        notifier.stop()
        frames = drain(recorder)
        net.disconnect()
        server_bus.shutdown()
        recorder.shutdown()
    assert read_big == big and objects[(0x2200, 0)] == payload

    upload, download = track(frames, SdoTracker())
    assert (upload.direction, upload.protocol, upload.result) == ("upload", "block", "ok")
    assert bytes.fromhex(upload.data) == big and upload.size == len(big)
    assert (download.direction, download.protocol, download.result) == ("download", "block", "ok")
    assert bytes.fromhex(download.data) == payload and download.index == 0x2200
    segments = -(-len(payload) // 7)
    assert download.frames == segments + 4 + _sub_blocks(segments, blksizes)


def _sub_blocks(segments: int, blksizes: tuple[int, ...]) -> int:
    count = 0
    while segments > 0:
        segments -= blksizes[min(count, len(blksizes) - 1)]
        count += 1
    return count


def test_a_long_download_is_shown_short_and_kept_whole(bus, tmp_path) -> None:
    """A 5000-byte DOMAIN download (a program download's shape) by canopen's client: the
    text line and the event message show its first 32 bytes and its size (the whole hex
    made a 10 kB line), the SDO table (read with pyarrow) keeps every byte."""
    import subprocess
    import sys

    import pyarrow.parquet as pq

    _, remote, recorder, _ = bus
    blob = bytes(k * 7 % 251 for k in range(5000))
    remote.sdo.download(0x2003, 0, blob)
    log = tmp_path / "blob.log"
    with can.Logger(str(log)) as writer:
        for msg in drain(recorder):
            writer(msg)
    cmd = [sys.executable, "-m", "cananalyze"]
    text = subprocess.run([*cmd, "decode", str(log)], capture_output=True, text=True).stdout
    (line,) = [ln for ln in text.splitlines() if "SDO write 0x2003" in ln]
    assert f"-> ok: data {blob[:32].hex()}... (5000 bytes)" in line and len(line) < 200
    out = tmp_path / "out"
    subprocess.run([*cmd, "export", str(log), "--parquet", str(out), "-q"], check=True)
    (sdo,) = pq.read_table(out / "sdo.parquet").to_pylist()
    assert (sdo["data"], sdo["size"]) == (blob.hex(), 5000)
    events = pq.read_table(out / "events.parquet").to_pylist()
    (msg,) = [e["message"] for e in events if e["kind"] == "sdo"]
    assert msg == f"SDO download 0x2003:00 data {blob[:32].hex()}... (5000 bytes) ok"


def test_an_abort_whose_request_is_not_in_the_log(bus, tmp_path) -> None:
    """A log that starts between python-canopen's request and its server's abort: every
    text says which COB-ID and node and that the start is not in the log, never `None`."""
    import subprocess
    import sys

    client_net, remote, recorder, od = bus
    with pytest.raises(SdoAbortedError):
        remote.sdo.upload(0x3000, 0)
    frames = drain(recorder)
    assert [m.arbitration_id for m in frames] == [0x605, 0x585]
    log = tmp_path / "late.log"
    log.write_text(f"({frames[1].timestamp:.6f}) vcan0 585#{frames[1].data.hex().upper()}\n")
    run = [sys.executable, "-m", "cananalyze"]
    text = subprocess.run([*run, "decode", str(log)], capture_output=True, text=True).stdout
    check = subprocess.run([*run, "check", str(log)], capture_output=True, text=True).stdout
    start = "abort by server on 0x585 (node 5), the transfer's start is not in the log"
    assert "node 5 SDO transfer 0x3000:00 -> abort: 0x06020000 " in text and start in text
    assert "sdo: SDO transfer 0x3000:00 abort: " in check and start in check
    assert "None" not in text + check


def test_block_segments_in_frame_records(tmp_path) -> None:
    """python-canopen's block download segments, as JSONL frame records: `seqno` and `last`
    (CiA 301: bit 7 is c, bits 0-6 the sequence number), no command specifier, no abort."""
    import json
    import subprocess
    import sys

    channel = unique_channel("block-json")
    objects = {(0x2200, 0): b""}
    server_bus = can.Bus(interface="virtual", channel=channel)
    server = BlockSdoServer(server_bus, NODE, objects, blksizes=(4,), crc=True)
    notifier = can.Notifier(server_bus, [server])
    recorder = can.Bus(interface="virtual", channel=channel)
    net = canopen.Network()
    net.connect(interface="virtual", channel=channel)
    remote = patient_client(NODE)
    net.add_node(remote)
    payload = b"CANopen block transfer, recorded"  # 32 bytes: 5 segments, sub-blocks of 4
    try:
        with remote.sdo.open(
            0x2200, 0, "wb", size=len(payload), block_transfer=True, request_crc_support=True
        ) as f:
            f.write(payload)
    finally:
        notifier.stop()
        frames = drain(recorder)
        net.disconnect()
        server_bus.shutdown()
        recorder.shutdown()
    log = tmp_path / "block.log"
    log.write_text(
        "".join(
            f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#{m.data.hex().upper()}\n"
            for m in frames
        )
    )
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--format", "jsonl"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    recs = [json.loads(x) for x in out.splitlines()]
    segs = [r for r in recs if r.get("command") == "block_segment"]
    assert [(s["seqno"], s["last"]) for s in segs] == [
        (1, False), (2, False), (3, False), (4, False), (1, True),
    ]  # fmt: skip
    assert bytes.fromhex("".join(s["sdo_data"] for s in segs))[: len(payload)] == payload
    for s in segs:
        assert not {"cs", "toggle", "c", "n", "abort_code", "abort_text"} & set(s), s
        assert s["index"] == 0x2200 and s["role"].startswith("block download segment")
    sdo = [r for r in recs if r.get("kind") == "sdo"]
    assert [(r["protocol"], r["result"], r["size"]) for r in sdo] == [("block", "ok", 32)]
