"""Replay the I-7231D manual's worked SDO examples (seed 002), frames exactly as printed.

The manual is the only text with the bytes of a complete block transfer; the
frames are typed here as its examples print them (node 1: 0x601 / 0x581) and
the test checks the seed still contains them, so a wrong transcription fails.
"""

from __future__ import annotations

import re

import pytest

from cananalyze.decode.sdo import SdoTracker
from cananalyze.protocol.datatypes import DATA_TYPES_BY_NAME
from cananalyze.protocol.sdo import describe_sdo
from tests.conftest import seed_file
from tests.helpers.sdo_frames import replay

REQ, RESP = 0x601, 0x581
VISIBLE_STRING = DATA_TYPES_BY_NAME["VISIBLE_STRING"].code
UNSIGNED8 = DATA_TYPES_BY_NAME["UNSIGNED8"].code

# Manual section 5.1.1, "SDO Upload Example" (normal transfer), steps 1-6.
SEGMENTED_UPLOAD_1008 = [
    (REQ, "40 08 10 00 00 00 00 00"),
    (RESP, "41 08 10 00 09 00 00 00"),
    (REQ, "60 00 00 00 00 00 00 00"),
    (RESP, "00 43 50 53 5F 44 43 4F"),
    (REQ, "70 00 00 00 00 00 00 00"),
    (RESP, "1B 4E 00 00 00 00 00 00"),
]
# Section 5.1.2, "SDO Block Upload Example", steps 1-8.
BLOCK_UPLOAD_1008 = [
    (REQ, "A0 08 10 00 7F 00 00 00"),
    (RESP, "C2 08 10 00 09 00 00 00"),
    (REQ, "A3 00 00 00 00 00 00 00"),
    (RESP, "01 43 50 53 5F 44 43 4F"),
    (RESP, "82 4E 00 00 00 00 00 00"),
    (REQ, "A2 02 7F 00 00 00 00 00"),
    (RESP, "D5 00 00 00 00 00 00 00"),
    (REQ, "A1 00 00 00 00 00 00 00"),
]
# Section 5.1.4, "SDO Block Download Example": 0x1400 sub 2 := 05 00, steps 1-6.
BLOCK_DOWNLOAD_1400_2 = [
    (REQ, "C0 00 14 02 00 00 00 00"),
    (RESP, "A0 00 14 02 7F 00 00 00"),
    (REQ, "81 05 00 00 00 00 00 00"),
    (RESP, "A2 01 7F 00 00 00 00 00"),
    (REQ, "D9 00 00 00 00 00 00 00"),
    (RESP, "A1 00 00 00 00 00 00 00"),
]
# Section 5.1.5, abort example: read of 0x1008 sub 1.
ABORT_1008_1 = [(REQ, "40 08 10 01 00 00 00 00"), (RESP, "80 08 10 01 11 00 09 06")]


def _objects(node: int, index: int, subindex: int):
    return {
        (0x1008, 0): ("Manufacturer device name", VISIBLE_STRING),
        (0x1400, 0): ("RPDO1 highest sub-index", UNSIGNED8),
        (0x1400, 2): ("RPDO1 transmission type", UNSIGNED8),
    }.get((index, subindex))


@pytest.fixture(scope="module")
def manual_text() -> str:
    return seed_file("002_8af3d3370e33cdbc.txt").read_text(errors="replace")


def test_frames_are_the_manuals(manual_text: str) -> None:
    # The OCR glues a bit column to some first bytes ("100 43 50 ...", "C2108 10"):
    # check the unambiguous tails of every frame against the text.
    flat = re.sub(r"\s+", " ", manual_text).upper().replace("O", "0")
    for _cob, text in (
        SEGMENTED_UPLOAD_1008 + BLOCK_UPLOAD_1008 + BLOCK_DOWNLOAD_1400_2 + ABORT_1008_1
    ):
        tail = text[9:] if text.endswith("00 00 00 00 00") else text[3:]
        assert tail in flat, text


def test_segmented_upload_of_1008() -> None:
    tracker = SdoTracker(object_info=_objects)
    roles = replay(tracker, SEGMENTED_UPLOAD_1008)
    assert [r.problem for r in roles] == [None] * 6
    assert roles[3].text == "segmented upload segment 1, toggle 0"
    assert roles[5].text == "segmented upload segment 2, toggle 1, last"
    (tx,) = tracker.pop_completed()
    assert (tx.direction, tx.protocol, tx.result) == ("upload", "segmented", "ok")
    assert (tx.index, tx.subindex, tx.node, tx.frames, tx.ref) == (0x1008, 0, 1, 6, 5)
    assert tx.size == 9 and bytes.fromhex(tx.data) == b"CPS_DCON\x00"
    assert tx.value == "CPS_DCON" and tx.name == "Manufacturer device name"
    assert tx.latency_ms == pytest.approx(1.0)


def test_block_upload_of_1008() -> None:
    tracker = SdoTracker(object_info=_objects)
    roles = replay(tracker, BLOCK_UPLOAD_1008)
    assert [r.problem for r in roles] == [None] * 8
    assert roles[3].command == roles[4].command == "block_segment"
    assert roles[4].text == "block upload segment 2/127, last"
    (tx,) = tracker.pop_completed()
    assert (tx.direction, tx.protocol, tx.result) == ("upload", "block", "ok")
    assert bytes.fromhex(tx.data) == b"CPS_DCON\x00" and tx.size == 9
    assert tx.value == "CPS_DCON"
    # Stateless decode does not pretend to know a block segment: 0x01 reads as a segment byte.
    assert describe_sdo(bytes.fromhex(BLOCK_UPLOAD_1008[3][1]), False)["command"] != "block_segment"


def test_block_download_to_1400_sub_2() -> None:
    tracker = SdoTracker(object_info=_objects)
    roles = replay(tracker, BLOCK_DOWNLOAD_1400_2)
    assert [r.problem for r in roles] == [None] * 6
    assert roles[2].text == "block download segment 1/127, last"
    (tx,) = tracker.pop_completed()
    assert (tx.direction, tx.protocol, tx.result) == ("download", "block", "ok")
    assert (tx.index, tx.subindex) == (0x1400, 2)
    # n = 6 in the end frame: 7 - n = 1 valid byte. (The manual says "the first 2 bytes
    # are valid", counting the seqno byte; its upload example counts the same way.)
    assert tx.data == "05" and tx.size == 1 and tx.value == 5


def test_abort_of_1008_sub_1() -> None:
    tracker = SdoTracker()
    roles = replay(tracker, ABORT_1008_1)
    assert roles[1].command == "abort"
    (tx,) = tracker.pop_completed()
    assert tx.result == "abort" and tx.abort_code == 0x06090011
    assert tx.abort_text == "Sub-index does not exist"
    assert (tx.index, tx.subindex, tx.direction) == (0x1008, 1, "upload")
    info = describe_sdo(bytes.fromhex(ABORT_1008_1[1][1]), False)
    assert (info["command"], info["index"], info["subindex"]) == ("abort", 0x1008, 1)
    assert info["abort_code"] == 0x06090011


@pytest.mark.parametrize(
    ("request_", "response", "direction", "index", "subindex", "data"),
    [
        # 5.1.1 expedited read of 0x1400 sub 0: n = 3, one valid byte.
        ("40 00 14 00 00 00 00 00", "4F 00 14 00 02 00 00 00", "upload", 0x1400, 0, "02"),
        # EMCY section: read of the error history 0x1003 sub 2, 4 bytes.
        ("40 03 10 02 00 00 00 00", "43 03 10 02 00 FF 0B 02", "upload", 0x1003, 2, "00ff0b02"),
        # PDO section step 12: RPDO1 transmission type 0x1400 sub 2 := 0 (n = 3).
        ("2F 00 14 02 00 00 00 00", "60 00 14 02 00 00 00 00", "download", 0x1400, 2, "00"),
        # Guarding example: guard time 0x100C := 250 (n = 2).
        ("2B 0C 10 00 FA 00 00 00", "60 0C 10 00 00 00 00 00", "download", 0x100C, 0, "fa00"),
    ],
)
def test_expedited(request_, response, direction, index, subindex, data, manual_text) -> None:
    flat = re.sub(r"\s+", " ", manual_text).upper().replace("O", "0")
    assert request_ in flat and response[3:] in flat
    tracker = SdoTracker()
    replay(tracker, [(REQ, request_), (RESP, response)])
    (tx,) = tracker.pop_completed()
    assert (tx.direction, tx.protocol, tx.result) == (direction, "expedited", "ok")
    assert (tx.index, tx.subindex, tx.data, tx.size) == (index, subindex, data, len(data) // 2)
    record = tx.to_record()
    assert record["kind"] == "sdo" and record["cob_ids"] == [REQ, RESP]
