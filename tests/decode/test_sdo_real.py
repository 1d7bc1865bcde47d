"""SDO decoding of real captures (hilch/canopen-message-interpreter) against their decode CSVs.

The CSVs are that project's own interpretation, one row per frame, numbered like
the trace: index/subindex of initiate frames and the text of abort codes must
agree with ours. Traces are read with python-can's TRCReader (PEAK) and a few
lines of csv (IXXAT) until cananalyze's own readers land.
"""

from __future__ import annotations

import csv
from collections import Counter
from pathlib import Path

import can
import pytest

from cananalyze.decode.sdo import SdoTracker
from cananalyze.protocol.sdo import ABORT_CODES, describe_sdo
from tests.conftest import real_file

FOLDER = "hilch__canopen-message-interpreter"
ABORT_BY_TEXT = {text.lower().rstrip("."): code for code, text in ABORT_CODES.items()}


def _peak(path: Path) -> list[tuple[float, int, bytes]]:
    return [(m.timestamp, m.arbitration_id, bytes(m.data)) for m in can.TRCReader(str(path))]


def _ixxat(path: Path) -> list[tuple[float, int, bytes]]:
    frames = []
    with path.open(newline="", encoding="latin-1") as f:
        rows = csv.reader(f, delimiter=";")
        for row in rows:
            if row and row[0] == "Time":
                break
        for row in rows:
            h, m, s = row[0].split(":")
            data = b"" if "Rtr" in row[3] else bytes.fromhex(row[4])
            frames.append((int(h) * 3600 + int(m) * 60 + float(s), int(row[1], 16), data))
    return frames


def _oracle(path: Path) -> dict[int, list[str]]:
    with path.open(newline="", encoding="utf-8", errors="replace") as f:
        return {
            int(r[0]): r for r in csv.reader(f, delimiter=";") if r and r[5] in ("SDO_R", "SDO_T")
        }


def _run(frames):
    tracker = SdoTracker()
    roles = {}
    for number, (t, cob, data) in enumerate(frames, start=1):
        if tracker.channel_of(cob) is not None:
            roles[number] = tracker.feed(t, cob, data, number)
    tracker.finish()
    return roles, tracker.pop_completed()


@pytest.mark.parametrize(
    ("name", "reader"), [("pcan1.trc", _peak), ("pcan2.trc", _peak), ("ixxat1.trc", _ixxat)]
)
def test_matches_third_party_decode(name, reader) -> None:
    frames = reader(real_file(f"{FOLDER}/{name}"))
    oracle = _oracle(real_file(f"{FOLDER}/{name}.csv"))
    roles, transactions = _run(frames)
    checked = aborts = 0
    for number, row in oracle.items():
        t, cob, data = frames[number - 1]
        assert f"0x{cob:04x}" == row[2].lower(), f"{name} frame {number}: numbering differs"
        is_request = row[5] == "SDO_R"
        info = describe_sdo(data, is_request)
        role = roles[number]
        if row[7] != "-":
            assert (role.index, role.subindex) == (int(row[7], 16), int(row[8])), (number, row)
            assert (info["index"], info["subindex"]) == (role.index, role.subindex)
            checked += 1
        if "abort transfer" in row[9]:
            their_text = row[9].split('"')[1].strip().lower().rstrip(".")
            if their_text.startswith("abort code:"):  # a code outside CiA 301's table
                their_code = int(their_text.split(":")[1], 16)
            else:
                their_code = ABORT_BY_TEXT[their_text]
            assert info["abort_code"] == their_code, (number, row)
            assert role.command == "abort"
            aborts += 1
    assert checked > 10
    assert all(role.problem is None for role in roles.values()), [
        (n, r) for n, r in roles.items() if r.problem
    ]
    results = Counter(tx.result for tx in transactions)
    assert results["abort"] == aborts
    _check_cut_short(frames, transactions)


def _check_cut_short(frames, transactions) -> None:
    """Every protocol error in these traces is a transfer the client abandoned mid-way:
    check independently that the next frame on its channel is a new initiate request."""
    for tx in transactions:
        if tx.result == "timeout":
            assert "new request" in tx.detail or "log ended" in tx.detail
        if tx.result != "protocol_error":
            continue
        assert tx.detail == "new request on the channel before this transfer ended"
        after = [(t, d) for t, c, d in frames[tx.ref :] if c == tx.channel[0] and t > tx.t]
        assert after and after[0][1][0] >> 5 in (1, 2, 5, 6), tx


def test_pcan3_has_no_protocol_errors() -> None:
    # No oracle for pcan3: its source documents ~10k SDO frames incl. segmented
    # uploads and 61 aborts; every transfer must close cleanly.
    roles, transactions = _run(_peak(real_file(f"{FOLDER}/pcan3.trc")))
    results = Counter(tx.result for tx in transactions)
    assert results["abort"] == 61
    assert results["protocol_error"] == 0
    _check_cut_short(_peak(real_file(f"{FOLDER}/pcan3.trc")), transactions)
    segmented = [tx for tx in transactions if tx.protocol == "segmented" and tx.result == "ok"]
    assert segmented and all(tx.size == len(bytes.fromhex(tx.data)) for tx in segmented)
