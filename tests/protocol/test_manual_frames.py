"""Frames printed in the device manuals decode to the manuals' meanings (stateless CiA 301 view)."""

from __future__ import annotations

import pytest
from conftest import seed_file

from cananalyze.core.frames import FLAG_RTR, from_rows
from cananalyze.protocol.cobid import CobClassifier
from cananalyze.protocol.fields import annotation, frame_fields
from cananalyze.protocol.services import SERVICE_NAMES


def _decode(rows):
    batch = from_rows(rows)
    c = CobClassifier().classify(batch)
    out = []
    for i in range(len(batch)):
        svc = int(c.service[i])
        f = frame_fields(svc, batch.payload(i), bool(batch.flags[i] & FLAG_RTR))
        out.append(
            (
                SERVICE_NAMES[svc],
                int(c.node[i]),
                f,
                annotation(svc, int(c.node[i]), int(c.pdo[i]), f),
            )
        )
    return out


def test_i7231d_nmt_guarding_emcy_sync():
    text = seed_file("002_8af3d3370e33cdbc.txt").read_text(encoding="utf-8", errors="replace")
    # the manual's frames, as printed (the OCR keeps these byte strings legible)
    assert "cs z 1 Node ID 5" in text and "COB ID 0x701" in text
    assert "FF 81 OB 01" in text and "30 81 11 07" in text and "COB ID 0x80" in text
    frames = _decode(
        [
            (0.0, 0x000, bytes([0x01, 0x05])),  # NMT start remote node 5
            (0.1, 0x701, b"", FLAG_RTR),  # node guarding request to node 1
            (0.2, 0x701, b"\x7f"),  # response: pre-operational, toggle 0
            (0.3, 0x081, bytes.fromhex("00FF810B01000000")),  # I-7231D EMCY: DCON module failure
            (0.4, 0x081, bytes.fromhex("3081110700000000")),  # guarding failure (life guard)
            (0.5, 0x080, b""),  # SYNC, no counter
            (0.6, 0x081, bytes(8)),  # error reset
        ]
    )
    nmt, rtr, resp, emcy1, emcy2, sync, reset = frames
    assert nmt[0] == "nmt" and nmt[2] == {"command": "start", "target": 5}
    assert nmt[3] == "NMT start node 5"
    assert rtr[0] == "guard_request" and rtr[1] == 1
    assert resp[0] == "guard_response" and resp[2] == {"state": "pre-operational", "toggle": 0}
    assert emcy1[0] == "emcy" and emcy1[1] == 1
    assert emcy1[2]["error_code"] == 0xFF00 and emcy1[2]["error_class"] == "Device specific"
    assert emcy1[2]["error_register"] == 0x81
    assert emcy1[2]["error_register_bits"] == ["generic", "manufacturer specific"]
    assert emcy1[2]["manufacturer"] == "0b01000000"  # vendor code 0x0B, module address 1
    assert emcy2[2]["error_code"] == 0x8130
    assert emcy2[2]["error_class"] == "Life guard error or heartbeat error"
    assert emcy2[2]["error_register_bits"] == ["generic", "communication"]
    assert sync[0] == "sync" and sync[2] == {"counter": None}
    assert reset[2]["reset"] is True and reset[3] == "EMCY error reset / no error"


@pytest.mark.parametrize(
    ("frame", "code", "klass", "register", "mfr"),
    [
        (
            "3081010000000010",
            0x8130,
            "Life guard error or heartbeat error",
            0x01,
            "0000000010",
        ),  # heartbeat error
        (
            "3081010000000020",
            0x8130,
            "Life guard error or heartbeat error",
            0x01,
            "0000000020",
        ),  # node guarding warning
        (
            "3081110000000030",
            0x8130,
            "Life guard error or heartbeat error",
            0x11,
            "0000000030",
        ),  # life guarding
        (
            "1023010001000000",
            0x2310,
            "Current, CANopen device output side",
            0x01,
            "0001000000",
        ),  # output overload
        ("0081010000000040", 0x8100, "Communication", 0x01, "0000000040"),  # CAN error warning
        (
            "40810100000000C0",
            0x8140,
            "Recovered from bus off",
            0x01,
            "00000000c0",
        ),  # return from bus off
    ],
)
def test_mcb560_emergency_list(frame, code, klass, register, mfr):
    text = seed_file("004_b12e0f30c6bded9a.txt").read_text(encoding="utf-8")
    assert " ".join(frame[i : i + 2] for i in range(0, 8, 2)).upper() in text.replace("\t", " ")
    [(svc, node, f, _)] = _decode([(0.0, 0x085, bytes.fromhex(frame))])
    assert svc == "emcy" and node == 5
    assert f["error_code"] == code and f["error_class"] == klass
    assert f["error_register"] == register
    assert f["manufacturer"] == mfr


def test_lss_and_time_and_other():
    """CiA 305 LSS exchanges by name, TIME_OF_DAY as a date, and non-CANopen IDs left alone."""
    frames = _decode(
        [
            (0.0, 0x7E5, bytes([0x04, 0x01]) + bytes(6)),  # switch state global: configuration
            (0.1, 0x7E5, bytes([0x11, 0x05]) + bytes(6)),  # configure node-ID 5
            (0.2, 0x7E4, bytes([0x11, 0x00]) + bytes(6)),  # slave: success
            (0.3, 0x7E5, bytes([0x5E]) + bytes(7)),  # inquire node-ID
            (0.4, 0x100, (100).to_bytes(4, "little") + (15341).to_bytes(2, "little")),
            (0.5, 0x18FF0001, b"\x01"),  # J1939-style 29-bit identifier
            (0.6, 0x7F0, b"\x01"),  # 11-bit, outside the predefined connection set
            (0.7, 0x180, b"\x01"),  # node-ID 0 is not a node
        ]
    )
    assert [f[0] for f in frames] == ["lss_master"] * 2 + ["lss_slave", "lss_master", "time"] + [
        "other"
    ] * 3
    assert [f[2]["command"] for f in frames[:4]] == [
        "switch state global",
        "configure node-ID",
        "configure node-ID",
        "inquire node-ID",
    ]
    assert frames[4][2]["time"] == "2026-01-01T00:00:00.100Z"
    assert all(f[1] == -1 for f in frames[5:])


def test_empty_lss_frame_says_what_is_wrong():
    """An LSS frame without its command specifier is named malformed, not "None"."""
    frames = _decode([(0.0, 0x7E5, b""), (0.1, 0x7E4, b""), (0.2, 0x7E5, bytes([0x5E]))])
    assert [f[2]["command"] for f in frames] == [None, None, "inquire node-ID"]
    assert frames[0][2]["problem"] == frames[1][2]["problem"] == "malformed: no command specifier"
    assert frames[0][3] == "LSS master (malformed: no command specifier)"
    assert frames[1][3] == "LSS slave (malformed: no command specifier)"
    assert "problem" not in frames[2][2] and frames[2][3] == "LSS master inquire node-ID"
    assert not any("None" in f[3] for f in frames)
