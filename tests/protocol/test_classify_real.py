"""Service classification against the third-party decode CSVs beside the hilch traces.

Their groups map onto ours: ERR_CTRL = heartbeat, boot-up and node guarding;
PDOn_T/PDOn_R = TPDOn/RPDOn; SDO_R (received by the server) = request; SDO_T = response.
Where we are finer than they are (guard responses they call "Heartbeat") the
test checks our reading independently: each such frame answers an RTR.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest
from conftest import real_file

from cananalyze.core.frames import FLAG_RTR
from cananalyze.formats.source import read_all
from cananalyze.protocol.cobid import CobClassifier
from cananalyze.protocol.services import SERVICE_NAMES

OURS_FOR = {
    "ERR_CTRL": {"heartbeat", "bootup", "guard_request", "guard_response"},
    "NMT": {"nmt"},
    "TIME": {"time"},
    "EMCY": {"emcy"},
    "SDO_R": {"sdo_request"},
    "SDO_T": {"sdo_response"},
    "NONE": {"other", "sync", "lss_master", "lss_slave"},
}


def _theirs(name: str, pdo: int) -> set[str]:
    if name.startswith("PDO"):
        return {("tpdo" if name.endswith("_T") else "rpdo") + str(int(name[3]))}
    return OURS_FOR[name]


@pytest.mark.parametrize("trace", ["pcan1.trc", "pcan2.trc", "ixxat1.trc"])
def test_classification_agrees_with_their_decode(trace):
    log = real_file(f"hilch__canopen-message-interpreter/{trace}")
    oracle = real_file(f"hilch__canopen-message-interpreter/{trace}.csv")
    with open(oracle, encoding="latin-1") as f:
        rows = list(csv.reader(f, delimiter=";"))[1:]
    batch = read_all(log)
    c = CobClassifier().classify(batch)
    assert len(batch) == len(rows)
    ours = [
        SERVICE_NAMES[s] + (str(p) if SERVICE_NAMES[s] in ("tpdo", "rpdo") else "")
        for s, p in zip(c.service.tolist(), c.pdo.tolist(), strict=True)
    ]
    mismatches = []
    guard_but_heartbeat = []
    for i, row in enumerate(rows):
        their_name, text = row[5], row[9]
        assert int(row[2], 16) == int(batch.can_id[i]), f"row {i + 1}: frame order differs"
        if ours[i] not in _theirs(their_name, 0):
            mismatches.append((i + 1, row[2], their_name, ours[i]))
        if ours[i] == "guard_response" and text.startswith("Heartbeat"):
            guard_but_heartbeat.append(i)
    assert mismatches == []
    # Their "Heartbeat" on a frame that answers a guarding RTR is a guard response:
    # the previous frame on that COB-ID is the RTR, and bit 7 is the toggle.
    for i in guard_but_heartbeat:
        prev = np.flatnonzero(batch.can_id[:i] == batch.can_id[i])[-1]
        assert batch.flags[prev] & FLAG_RTR
    if trace != "pcan1.trc":
        assert guard_but_heartbeat, "the guarded nodes of these traces answer RTRs"
