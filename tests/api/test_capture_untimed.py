"""load() on a log without times (candump's screen output): what needs time is given by
line (issue 44)."""

from __future__ import annotations

import numpy as np

import cananalyze
from tests.conftest import real_file


def test_signals_wide_of_a_log_without_times_is_indexed_by_line():
    """ZeroErr's log2 has no times: 1,182 signal values were folded into one row at t=0."""
    log = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    cap = cananalyze.load(log, device={11: "cia402"})
    wide = cap.signals_wide()
    assert wide.index.name == "line" and wide.index.is_monotonic_increasing
    sig = cap.signals
    assert wide.notna().to_numpy().sum() == len(sig) == 1182
    # each value at its frame's line, as the long table has it
    status = sig[sig.signal == "statusword"]
    (cob,) = set(status.cob_id)
    col = next(c for c in wide.columns if c.endswith("/statusword"))
    got = wide[col].dropna()
    assert np.array_equal(got.to_numpy(), status.value.to_numpy(np.float64))
    # the lines of the file that hold that PDO, counted here from the text itself
    lines = [
        k
        for k, text in enumerate(log.read_text().splitlines(), start=1)
        if len(text.split()) > 1 and text.split()[1].upper() == f"{cob:03X}"
    ]
    assert got.index.tolist() == lines
