"""Every decoder against any frame: no exception, JSON always valid (issue 9).

Hostile frames on any identifier, with any flags and 0..64 payload bytes, go
through the classifier, the stateless field decoders, the SDO tracker, the full
Decoder of `decode`, and both writers.
"""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cananalyze.core.frames import FLAG_RTR
from cananalyze.decode.sdo.tracker import SdoTracker
from cananalyze.protocol.cobid import CobClassifier
from cananalyze.protocol.fields import annotation, frame_fields
from cananalyze.protocol.sdo import describe_sdo
from cananalyze.protocol.services import SERVICE_NAMES
from tests.fuzz.harness import decode_all
from tests.fuzz.strategies import frame_rows, fuzz_settings, make_batch, payloads

FAST = fuzz_settings(300)


@FAST
@given(
    st.integers(0, len(SERVICE_NAMES) - 1),
    payloads,
    st.booleans(),
    st.integers(-1, 127),
    st.integers(0, 4),
)
def test_fields_and_annotation_any_payload(service, data, rtr, node, pdo):
    fields = frame_fields(service, data, rtr)
    assert isinstance(fields, dict)
    text = annotation(service, node, pdo, fields, rtr)
    assert isinstance(text, str) and "\n" not in text
    json.dumps(fields, default=str)


@FAST
@given(payloads, st.booleans())
def test_describe_sdo_any_payload(data, is_request):
    out = describe_sdo(data, is_request)
    assert isinstance(out, dict)
    json.dumps(out, default=str)


@FAST
@given(st.lists(frame_rows, max_size=60))
def test_classifier_any_batch(rows):
    b = make_batch(rows)
    c = CobClassifier().classify(b)
    assert len(c.service) == len(b) and len(c.node) == len(b)
    assert (c.service < len(SERVICE_NAMES)).all()
    assert ((c.node >= -1) & (c.node <= 127)).all()


@FAST
@given(
    st.lists(
        st.tuples(st.floats(-10, 10, allow_nan=False), st.integers(0x580, 0x67F), payloads),
        max_size=80,
    )
)
def test_sdo_tracker_any_sequence(frames):
    """Random SDO traffic (times may go backwards): every transaction ends in a known result."""
    tracker = SdoTracker(timeout=0.5)
    for k, (t, cob, data) in enumerate(frames):
        tracker.feed(t, cob, data, k)
        tracker.advance(t)
    tracker.finish()
    for tx in tracker.pop_completed():
        rec = tx.to_record()
        assert rec["result"] in ("ok", "abort", "timeout", "protocol_error")
        json.dumps(rec, allow_nan=False)


@fuzz_settings(150)
@given(st.lists(st.lists(frame_rows, max_size=40), min_size=1, max_size=4), st.booleans())
@pytest.mark.slow
def test_full_decoder_and_writers(batches, sort):
    """The decode pipeline over several batches: text and JSONL without error, JSON valid."""
    n, jsonl, text = decode_all(make_batch(rows, sort) for rows in batches)
    assert n == sum(len(r) for r in batches)
    frames = [json.loads(x) for x in jsonl.split("\n")[:-1] if '"kind":"frame"' in x]
    assert len(frames) == n
    for rec in frames:
        assert rec["service"] in SERVICE_NAMES
        assert rec.get("rtr") or len(rec["data"]) == 2 * rec["dlc"]


def test_rtr_frame_keeps_its_dlc_without_data():
    b = make_batch([(0.0, 0x70A, b"\0", FLAG_RTR, 0)])
    _, jsonl, _ = decode_all([b])
    rec = json.loads(jsonl.split("\n")[0])
    assert rec["rtr"] is True and rec["data"] == "" and rec["service"] == "guard_request"
