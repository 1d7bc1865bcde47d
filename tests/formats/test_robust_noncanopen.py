"""Non-CANopen buses are called what they are: the summary's verdict on real and J1939 traffic."""

from __future__ import annotations

import pytest
from conftest import real_file

from cananalyze.core.frames import from_rows
from cananalyze.formats.source import open_log
from cananalyze.outputs.summary import Summary
from cananalyze.pipeline import Options, build_decoder


def _summary(batches) -> Summary:
    decoder = build_decoder(Options())
    s = Summary()
    for fb in batches:
        s.add(decoder.decode(fb))
    s.add(decoder.finish())
    return s


def verdict(rel: str) -> str | None:
    return _summary(open_log(real_file(rel)).batches()).canopen_verdict()


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan1.trc",
        "hilch__canopen-message-interpreter/pcan2.trc",  # 64 % manufacturer/TIME frames: still CANopen
        "hilch__canopen-message-interpreter/ixxat1.trc",
        "isPointless__Sevcon/can_230309_150427.txt",  # 64 % manufacturer PDOs 0x122..0x125
        "isPointless__Sevcon/can_310309_094758.txt",
        "jclinton830__canopen_test/candump.txt",
        "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
        "SeonilChoi__CANOPEN-SDK/log2.txt",
    ],
)
def test_canopen_logs_get_no_verdict(rel):
    assert verdict(rel) is None


def test_zeroerr_proprietary_protocol_is_not_sdo():
    """0x64B/0x5CB carry ZeroErr's own 2..5-byte protocol, not SDO of node 75."""
    v = verdict("SeonilChoi__CANOPEN-SDK/log.txt")
    assert v.startswith("Not SDO: 1382 of 1382 frames on SDO identifiers (0x5CB, 0x64B)")


@pytest.mark.parametrize(
    "rel", ["collin80__SavvyCAN/candump.log", "collin80__SavvyCAN/GVRET_Log.csv"]
)
def test_car_bus_heartbeat_range_is_not_error_control(rel):
    v = verdict(rel)
    assert v.startswith(
        "Not CANopen error control: 658 of 658 frames on heartbeat identifiers (0x754"
    )


@pytest.mark.parametrize(
    "rel",
    [
        "collin80__SavvyCAN/CarBusAnalyzer.trc",
        "hardbyte__python-can/issue_1256.asc",
        "hardbyte__python-can/logfile.asc",
    ],
)
def test_other_buses_do_not_look_like_canopen(rel):
    assert verdict(rel).startswith("This does not look like CANopen:")


def test_j1939_traffic_is_named():
    rows = []
    for i in range(300):  # engine speed (PGN 61444), vehicle speed (65265), DM1 (65226)
        for pgn, sa in ((0xF004, 0x00), (0xFEF1, 0x00), (0xFECA, 0x03)):
            rows.append(
                (
                    i * 0.01,
                    (3 << 26) | (pgn << 8) | sa,
                    bytes([i % 256, 0xFF, 0x20, 0x1F, 0, 0, 0xFF, 0xFF]),
                )
            )
    v = _summary([from_rows(rows)]).canopen_verdict()
    assert v.startswith(
        "This does not look like CANopen: 900 of 900 frames have 29-bit identifiers"
    )


def test_sdo_channel_of_protocol_errors_is_flagged():
    """8-byte frames on 0x60A/0x58A whose command bytes make no SDO sense, answered every time."""
    rows = []
    for i in range(20):
        rows.append(
            (i * 0.1, 0x60A, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]))
        )  # upload request 1000:00
        rows.append(
            (i * 0.1 + 0.01, 0x58A, bytes([0x20, 0x00, 0x10, 0, 1, 2, 3, 4]))
        )  # a download-segment cs
    rows += [(2.5, 0x70A, b"\x05")]
    s = _summary([from_rows(rows)])
    results = set(s.sdo_results[10])
    assert results == {"protocol_error"}, results
    assert (
        "Node 10's SDO channel is probably not SDO: 20 of 20 transactions are protocol errors."
        in (s.canopen_verdict() or "")
    )


def test_empty_log_verdict():
    assert _summary([]).canopen_verdict() == "The log holds no frames."
