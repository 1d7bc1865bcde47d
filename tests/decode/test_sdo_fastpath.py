"""The SDO fast path gives exactly the tracker's records, notes and end-of-log records.

Each input is decoded twice, once with `SdoProcessor(fast=False)` (every frame
through the tracker) and once with the fast path, in several batch sizes so
pairs cut by a batch boundary are covered; every note and record must match.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SAMPLES, real_file
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cananalyze.core.frames import FrameBatch, concat, from_rows
from cananalyze.decode.sdo.processor import SdoProcessor
from cananalyze.decode.sdo.tracker import SdoTracker
from cananalyze.formats.source import open_log
from cananalyze.pipeline import Decoder

sys.path.insert(0, str(ROOT / "benchmarks"))


def _object_info(node: int, index: int, sub: int):
    if index == 0x1018:
        return (f"Identity {sub}", 0x07)
    if index == 0x6041:
        return ("Statusword", 0x06)
    return None


def _run(fb: FrameBatch, fast: bool, step: int, object_info=None) -> tuple[list, dict, list]:
    proc = SdoProcessor(SdoTracker(timeout=0.5, object_info=object_info), fast=fast)
    dec = Decoder([proc])
    records: list = []
    notes: dict = {}
    for start in range(0, max(len(fb), 1), step):
        out = dec.decode(fb.take(slice(start, start + step)))
        records += [(start + row, rec) for row, rec in out.records]
        notes.update({start + row: note for row, note in out.notes.items()})
    tail = dec.finish()
    return records, notes, [rec for _, rec in tail.records]


def assert_same(fb: FrameBatch, steps=(1 << 20, 997, 64, 7), object_info=None) -> int:
    for step in steps:
        slow = _run(fb, False, step, object_info)
        fast = _run(fb, True, step, object_info)
        assert fast[1] == slow[1], f"notes differ (batch size {step})"
        assert fast[0] == slow[0], f"records differ (batch size {step})"
        assert fast[2] == slow[2], f"end-of-log records differ (batch size {step})"
    return len(slow[0]) + len(slow[2])


def _read(path: Path) -> FrameBatch:
    src = open_log(path)
    return concat(list(src.batches()))


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/ixxat1.trc",
        "hilch__canopen-message-interpreter/pcan1.trc",
        "hilch__canopen-message-interpreter/pcan2.trc",
        "hilch__canopen-message-interpreter/pcan3.trc",
        "isPointless__Sevcon/can_180209_154604.txt",
        "isPointless__Sevcon/can_230309_150427.txt",
        "isPointless__Sevcon/can_280109_111603.txt",
        "isPointless__Sevcon/can_310309_094758.txt",
        "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
        "SeonilChoi__CANOPEN-SDK/log.txt",
        "SeonilChoi__CANOPEN-SDK/log2.txt",
    ],
)
@pytest.mark.slow
def test_real_logs(rel: str) -> None:
    fb = _read(real_file(rel))
    assert len(fb)
    assert_same(fb, object_info=_object_info)


@pytest.mark.parametrize("name", ["demo.log", "demo.asc", "demo.blf"])
def test_samples(name: str) -> None:
    assert assert_same(_read(SAMPLES / name)) > 0


def test_benchmark_mix_mostly_fast() -> None:
    from generate import generate

    fb = generate(60_000)
    n = assert_same(fb, steps=(1 << 20, 4096, 333))
    assert n > 1000
    # and the shortcut is really taken: the tracker sees few frames
    proc = SdoProcessor(SdoTracker())
    calls = []
    feed = proc.tracker.feed
    proc.tracker.feed = lambda *a: calls.append(1) or feed(*a)
    Decoder([proc]).decode(fb)
    assert len(calls) < n / 5


# -- hypothesis: random SDO traffic -------------------------------------------------

_REQ = [
    0x40,
    0x22,
    0x23,
    0x27,
    0x2B,
    0x2F,
    0x41,
    0x21,
    0x20,
    0xA4,
    0xC6,
    0x60,
    0x80,
    0x00,
    0x10,
    0x62,
]
_RESP = [0x43, 0x4F, 0x42, 0x4B, 0x47, 0x60, 0x80, 0x41, 0x00, 0x10, 0x61, 0xC4, 0xA2, 0x20]
_MUX = [(0x1018, 1), (0x6041, 0), (0x2000, 3), (0x1017, 0)]


@st.composite
def traffic(draw):
    nodes = draw(st.lists(st.integers(1, 3), min_size=1, max_size=40))
    t = 0.0
    rows = []
    for node in nodes:
        mux = draw(st.sampled_from(_MUX))
        kind = draw(st.integers(0, 9))
        t += draw(st.sampled_from([0.0001, 0.001, 0.2, 0.6, 1.5]))
        req = bytes([draw(st.sampled_from(_REQ)), mux[0] & 0xFF, mux[0] >> 8, mux[1]]) + bytes(
            draw(st.lists(st.integers(0, 255), min_size=4, max_size=4))
        )
        if draw(st.integers(0, 9)) == 0:
            req = req[: draw(st.integers(0, 7))]  # short frame
        rows.append((t, 0x600 + node, req))
        if kind == 0:
            continue  # lost response
        t += draw(st.sampled_from([0.0001, 0.002, 0.45, 0.7]))
        rmux = mux if kind != 1 else draw(st.sampled_from(_MUX))
        resp = bytes([draw(st.sampled_from(_RESP)), rmux[0] & 0xFF, rmux[0] >> 8, rmux[1]]) + bytes(
            draw(st.lists(st.integers(0, 255), min_size=4, max_size=4))
        )
        if kind == 2:  # the answer comes from another node's server
            node = node % 3 + 1
        rows.append((t, 0x580 + node, resp))
        if kind == 3:  # a stray extra frame on the channel
            rows.append((t + 0.0001, 0x600 + node, bytes([0x80, 0, 0x20, 3, 0, 0, 4, 6])))
    # occasional reordering of neighbours
    swaps = draw(st.lists(st.integers(0, max(len(rows) - 2, 0)), max_size=4))
    for s in swaps:
        if s + 1 < len(rows):
            rows[s], rows[s + 1] = rows[s + 1], rows[s]
    return from_rows(rows)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(traffic(), st.sampled_from([1000, 5, 3, 2]))
@pytest.mark.slow
def test_random_traffic(fb: FrameBatch, step: int) -> None:
    assert_same(fb, steps=(step,), object_info=_object_info)


def test_pair_values_match_known_frames() -> None:
    """A hand-made pair: upload of 0x1018:01 answered with 4 bytes, a write aborted."""
    fb = from_rows(
        [
            (1.0, 0x605, bytes([0x40, 0x18, 0x10, 1, 0, 0, 0, 0])),
            (1.0005, 0x585, bytes([0x43, 0x18, 0x10, 1, 0x78, 0x56, 0x34, 0x12])),
            (2.0, 0x605, bytes([0x2B, 0x17, 0x10, 0, 0xE8, 0x03, 0, 0])),
            (2.001, 0x585, bytes([0x80, 0x17, 0x10, 0, 0x02, 0x00, 0x01, 0x06])),
        ]
    )
    proc = SdoProcessor(SdoTracker(object_info=_object_info))
    out = Decoder([proc]).decode(fb)
    (r1, up), (r2, down) = out.records
    assert (r1, r2) == (1, 3)
    assert up["value"] == 0x12345678 and up["data"] == "78563412" and up["latency_ms"] == 0.5
    assert down["result"] == "abort" and down["abort_code"] == 0x06010002
    assert down["data"] == "e803" and down["size"] == 2 and down["detail"] == "aborted by server"
    assert out.notes[1]["role"] == "expedited upload response 0x1018:01 = 78563412"
    assert np.all(proc.tracker._pending == {})


def test_short_frame_between_request_and_answer_breaks_the_pair() -> None:
    """A frame the fast path cannot take (0 bytes) still sits on the channel: the tracker
    fails the transfer there, so the answer is "after a protocol error", not a fast pair."""
    up = bytes([0x40, 0x18, 0x10, 1, 0, 0, 0, 0])
    fb = from_rows(
        [
            (0.0001, 0x601, b""),
            (0.0005, 0x601, up),
            (0.0006, 0x601, b""),
            (0.0007, 0x581, bytes([0x43, 0x18, 0x10, 1, 0, 0, 0, 0])),
        ]
    )
    assert_same(fb, steps=(1000, 2), object_info=_object_info)


def _fed(fb: FrameBatch, step: int) -> list[int]:
    """Rows (of the whole log) the fast path sent to the tracker, in batches of `step`."""
    proc = SdoProcessor(SdoTracker(timeout=0.5, object_info=_object_info))
    rows: list[int] = []
    feed = proc.tracker.feed
    proc.tracker.feed = lambda t, cob, data, ref: rows.append(ref) or feed(t, cob, data, ref)
    dec = Decoder([proc])
    for start in range(0, len(fb), step):
        dec.decode(fb.take(slice(start, start + step)))
    dec.finish()
    return rows


def test_stray_responses_on_idle_channels_take_the_shortcut() -> None:
    """Initiate responses no request asked for (a log that starts mid-poll, a lost
    request: half of what fell back on the benchmark's bus) get the tracker's notes
    without going through it, while their channel is idle; on a channel with a
    transfer in progress the tracker still takes them (there they fail it)."""
    up = bytes([0x40, 0x18, 0x10, 1, 0, 0, 0, 0])
    answer = bytes([0x43, 0x18, 0x10, 1, 0x78, 0x56, 0x34, 0x12])
    rows = [
        (0.001, 0x581, answer),  # stray upload response, idle channel
        (0.002, 0x582, bytes([0x60, 0x17, 0x10, 0, 0, 0, 0, 0])),  # stray download response
        (0.003, 0x603, up),
        (0.004, 0x583, answer),  # a fast pair
        (0.005, 0x604, bytes([0x40, 0x00, 0x60, 1, 0, 0, 0, 0])),
        (0.006, 0x584, bytes([0x60, 0x00, 0x60, 1, 0, 0, 0, 0])),  # wrong answer: 4 pending
        (0.007, 0x584, answer),  # stray on the failed channel: the tracker's
        (0.008, 0x581, answer),  # stray on an idle channel while 4 is pending
        (0.009, 0x601, up),
        (0.010, 0x581, answer),
        (2.0, 0x584, answer),  # after 4 timed out: idle again
    ]
    fb = from_rows(rows)
    assert_same(fb, steps=(1000, 5, 3, 2, 1), object_info=_object_info)
    out = Decoder([SdoProcessor(SdoTracker(timeout=0.5, object_info=_object_info))]).decode(fb)
    assert out.notes[0] == {
        "role": "initiate upload response",
        "command": "initiate_upload_response",
        "index": 0x1018,
        "subindex": 1,
        "sdo_problem": "initiate_upload_response with no transfer in progress",
    }
    assert out.notes[1]["sdo_problem"] == "initiate_download_response with no transfer in progress"
    assert out.notes[6]["role"].endswith("after a protocol error")
    # the tracker saw only the failed transfer's frames (4, 5, 6), whatever the batch size
    for step in (1000, 4):
        assert _fed(fb, step) == [4, 5, 6]


def test_benchmark_strays_are_not_fed() -> None:
    """On the benchmark's traffic the tracker now sees only the transfers that go wrong:
    no stray response on an idle channel is fed to it."""
    from generate import generate

    fb = generate(60_000)
    fed = _fed(fb, 1 << 20)
    d = fb.data[fed]
    stray = (fb.can_id[fed] >= 0x581) & (fb.can_id[fed] <= 0x5FF) & np.isin(d[:, 0] >> 5, (2, 3))
    # every response fed answers a request the tracker holds (the one fed just before it
    # on that channel)
    fed_set = {(int(fb.can_id[r]) - 0x580, r) for r in np.asarray(fed)[stray].tolist()}
    for node, r in fed_set:
        earlier = [q for q in fed if q < r and int(fb.can_id[q]) == 0x600 + node]
        assert earlier, f"stray response at row {r} went through the tracker"


def _canopen_session(node: int, block: bool) -> list:
    """python-canopen's client against its own server (or the block server), recorded."""
    import can
    import canopen
    from canopen.objectdictionary import UNSIGNED32, VISIBLE_STRING
    from canopen.sdo.exceptions import SdoAbortedError

    from tests.helpers.sdo_block_server import BlockSdoServer
    from tests.helpers.virtual_bus import drain, patient_client, unique_channel, variable

    channel = unique_channel("fast-sdo")
    recorder = can.Bus(interface="virtual", channel=channel)
    client = canopen.Network()
    client.connect(interface="virtual", channel=channel)
    remote = patient_client(node)
    client.add_node(remote)
    stop = []
    if block:
        server_bus = can.Bus(interface="virtual", channel=channel)
        objects = {(0x2100, 0): bytes(range(200)) * 3, (0x2101, 0): b"ab"}
        notifier = can.Notifier(server_bus, [BlockSdoServer(server_bus, node, objects)])
        stop = [notifier.stop, server_bus.shutdown]
    else:
        server = canopen.Network()
        server.connect(interface="virtual", channel=channel)
        od = canopen.ObjectDictionary()
        od.add_object(variable(0x1008, 0, "Name", VISIBLE_STRING, "ro", "a segmented name" * 3))
        od.add_object(variable(0x2000, 0, "Counter", UNSIGNED32, "rw", 7))
        server.add_node(canopen.LocalNode(node, od))
        stop = [server.disconnect]
    try:
        if block:
            with remote.sdo.open(0x2100, 0, "rb", block_transfer=True) as f:
                assert len(f.read()) == 600
            with remote.sdo.open(0x2200, 0, "wb", size=300, block_transfer=True) as f:
                f.write(bytes(300))
        else:
            for k in range(5):
                remote.sdo.download(0x2000, 0, struct_u32(k))
                assert remote.sdo.upload(0x2000, 0) == struct_u32(k)
                assert remote.sdo.upload(0x1008, 0).startswith(b"a segmented")
            with pytest.raises(SdoAbortedError):
                remote.sdo.upload(0x3000, 0)
    finally:
        frames = drain(recorder)
        for s in stop:
            s()
        client.disconnect()
        recorder.shutdown()
    return frames


def struct_u32(v: int) -> bytes:
    return v.to_bytes(4, "little")


@pytest.mark.slow
def test_canopen_traffic_of_several_servers_interleaved() -> None:
    """Expedited and segmented transfers and an abort (python-canopen's client and server,
    nodes 5 and 6) and block transfers (node 7), merged in time so the servers' transfers
    interleave, in batch sizes that cut transfers: the fast path's notes and records are
    the tracker's."""
    sessions = [_canopen_session(5, False), _canopen_session(6, False), _canopen_session(7, True)]
    rows = []
    for frames in sessions:
        t0 = frames[0].timestamp
        # spread each session over the same second, keeping its own order
        span = max(frames[-1].timestamp - t0, 1e-6)
        rows += [
            (0.001 + (m.timestamp - t0) / span, m.arbitration_id, bytes(m.data)) for m in frames
        ]
    rows.sort(key=lambda r: r[0])
    fb = from_rows(rows)
    n = assert_same(fb, steps=(1 << 20, 97, 13, 5, 2), object_info=_object_info)
    assert n >= 5 * 3 + 1 + 2 * 2 + 2


def test_request_that_cuts_a_transfer_short_takes_the_shortcut() -> None:
    """A clean expedited request on a channel whose transfer is still open (failed,
    unanswered or mid-segmented) ends that transfer as the tracker would and is taken as
    a fast pair with its answer; inside a block download's sub-block the same bytes are a
    segment, so that one goes through the tracker."""
    up = bytes([0x40, 0x00, 0x60, 1, 0, 0, 0, 0])
    answer = bytes([0x43, 0x00, 0x60, 1, 9, 0, 0, 0])
    rows = [
        (0.001, 0x601, up),
        (0.002, 0x581, bytes([0x43, 0x01, 0x60, 1, 9, 0, 0, 0])),  # names another object
        (0.003, 0x601, up),  # 2: cuts the failed transfer short
        (0.004, 0x581, answer),
        (0.005, 0x602, up),  # unanswered
        (0.006, 0x602, up),  # 5: the client's retry
        (0.007, 0x582, answer),
        (0.008, 0x603, bytes([0x40, 0x08, 0x10, 0, 0, 0, 0, 0])),
        (0.009, 0x583, bytes([0x41, 0x08, 0x10, 0, 20, 0, 0, 0])),  # segmented upload begins
        (0.010, 0x603, up),  # 9: new request mid-transfer
        (0.011, 0x583, answer),
        (0.012, 0x604, bytes([0xC2, 0x50, 0x1F, 1, 20, 0, 0, 0])),  # block download
        (0.013, 0x584, bytes([0xA4, 0x50, 0x1F, 1, 4, 0, 0, 0])),  # blksize 4: segments
        (0.014, 0x604, up),  # 13: a segment (seqno 64) here, not a request
        (0.015, 0x584, answer),
    ]
    fb = from_rows(rows)
    assert_same(fb, steps=(1000, 7, 4, 3, 2, 1), object_info=_object_info)
    fed = _fed(fb, 1000)  # (a pair cut by a batch boundary goes through the tracker)
    assert not {2, 3, 5, 6, 9, 10} & set(fed) and 13 in fed
    tail = Decoder([SdoProcessor(SdoTracker(timeout=0.5, object_info=_object_info))])
    out = tail.decode(fb)
    results = [(r["node"], r["result"]) for _, r in out.records]
    assert results == [(1, "protocol_error"), (1, "ok"), (2, "timeout"), (2, "ok"),
                       (3, "protocol_error"), (3, "ok")]  # fmt: skip
