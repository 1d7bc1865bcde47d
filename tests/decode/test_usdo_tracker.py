"""The USDO tracker alone (decode/sdo/usdo.py): how transfers end when the log misbehaves.

Frames as in test_usdo.py (the layouts protocol/usdo.py takes from EmSA's CiA 1301 codec
and emtas' `ico_usdo.h`); built with the table's encoder, which test_usdo.py checks against
the frames EmSA's codec wrote and bytes written out by hand."""

from __future__ import annotations

from cananalyze.decode.sdo.usdo import UsdoTracker
from cananalyze.protocol import usdo

REQ, RESP = 0x600 + 0x10, 0x580 + 5


def req(cs, session, **f):
    return REQ, usdo.encode(cs, 5, session, **f)


def resp(cs, session, **f):
    return RESP, usdo.encode(cs, 0x10, session, **f)


def run(frames, t0=1.0, step=0.001, end=True):
    tr = UsdoTracker(timeout=0.5)
    notes = [tr.feed(t0 + i * step, cob, data, i) for i, (cob, data) in enumerate(frames)]
    if end:
        tr.finish()
    return [rec for _, rec in tr.pop_completed()], notes


def test_sessions_of_one_client_run_side_by_side():
    recs, _ = run([
        req(0x11, 1, index=0x1000, subindex=0),
        req(0x11, 2, index=0x1001, subindex=0),
        resp(0x31, 2, index=0x1001, subindex=0, datatype=5, data=b"\x01"),
        resp(0x31, 1, index=0x1000, subindex=0, datatype=7, data=b"\x91\x01\x02\x00"),
    ])  # fmt: skip
    assert [(r["session"], r["index"], r["value"]) for r in recs] == [
        (2, 0x1001, 1), (1, 0x1000, 0x00020191)]  # fmt: skip


def test_a_request_never_answered_times_out_and_a_new_one_cuts_it_short():
    tr = UsdoTracker(timeout=0.5)
    tr.feed(1.0, *req(0x11, 1, index=0x1000, subindex=0), 0)
    tr.advance(2.0)
    ((ref, rec),) = tr.pop_completed()
    assert rec["result"] == "timeout" and ref is None
    recs, _ = run([req(0x11, 3, index=0x1000, subindex=0), req(0x11, 3, index=0x1001, subindex=0),
                   resp(0x31, 3, index=0x1001, subindex=0, datatype=5, data=b"\x07")])  # fmt: skip
    assert [r["result"] for r in recs] == ["timeout", "ok"]


def test_a_segment_counter_gap_is_noted():
    recs, notes = run([
        req(0x11, 1, index=0x1008, subindex=0),
        resp(0x32, 1, index=0x1008, subindex=0, datatype=9, total=6),
        resp(0x33, 1, counter=0, data=b"abc"),
        resp(0x33, 1, counter=2, data=b"de"),
        resp(0x34, 1, data=b"f"),
    ])  # fmt: skip
    assert recs[0]["result"] == "ok" and recs[0]["value"] == "abcdef"
    assert "segment counter 2 after 0" in recs[0]["detail"]
    assert notes[3]["usdo_problem"] == "segment counter 2 after 0"
    assert "usdo_problem" not in notes[4]  # the last segment's byte 3 is its size


def test_a_lone_abort_and_an_answer_without_request():
    recs, notes = run([
        resp(0x7F, 9, index=0x2000, subindex=0, abort_code=0x70),
        resp(0x21, 4, index=0x2000, subindex=0),
    ])  # fmt: skip
    assert [(r["result"], r["abort_text"]) for r in recs] == [("abort", "USDO server busy")]
    assert "the transfer's start is not in the log" in recs[0]["detail"]
    assert "no USDO transfer in progress" in notes[1]["usdo_problem"]


def test_a_wrong_sender_a_remote_frame_and_a_short_one():
    _, notes = run([
        (REQ, usdo.encode(0x31, 5, 1, index=0x1000, subindex=0, datatype=7, data=b"1234")),
        (REQ, bytes([5, 0x81, 1]) + bytes(5)),
        (REQ, bytes([5, 0x01])),
    ], end=False)  # fmt: skip
    assert "sent by a client" in notes[0]["usdo_problem"]
    assert notes[1]["role"].startswith("remote (routed) download expedited request")
    assert notes[2]["command"] == "invalid"


def test_the_log_ending_mid_transfer():
    recs, _ = run([
        req(0x11, 1, index=0x1008, subindex=0),
        resp(0x32, 1, index=0x1008, subindex=0, datatype=9, total=100),
    ])  # fmt: skip
    assert recs[0]["result"] == "protocol_error" and "log ended mid-transfer" in recs[0]["detail"]


def test_an_empty_last_segment_ends_an_upload():
    """CiA 1301's last segment may carry 0 bytes (EmSA's codec: n 0..60), after full ones."""
    body = bytes(range(120))
    recs, notes = run([
        req(0x11, 2, index=0x2040, subindex=0),
        resp(0x32, 2, index=0x2040, subindex=0, datatype=0x0F, total=120),
        req(0x13, 2, counter=0), resp(0x33, 2, counter=0, data=body[:60]),
        req(0x13, 2, counter=1), resp(0x33, 2, counter=1, data=body[60:]),
        req(0x13, 2, counter=2), resp(0x34, 2, data=b""),
    ])  # fmt: skip
    assert [(r["result"], r["size"], r["data"]) for r in recs] == [("ok", 120, body.hex())]
    assert not [n for n in notes if "usdo_problem" in n]
