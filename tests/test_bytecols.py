"""Text built column-wise (`bytecols`) equals Python's own formatting."""

from __future__ import annotations

import numpy as np

from cananalyze import bytecols

EDGES = [0, 1, 9, 10, -1, -9, -10, 255, 4096, 2**31 - 1, -(2**31), 2**32 - 1, 2**63 - 1, -(2**63)]


def _rows(matrix: np.ndarray) -> list[str]:
    blob, ends = bytecols.compact([matrix], len(matrix), True)
    return bytecols.split_rows(blob, ends)


def test_decimal_and_hex_equal_python() -> None:
    rng = np.random.default_rng(3)
    values = np.array(EDGES + rng.integers(-(2**40), 2**40, 2000).tolist(), np.int64)
    assert _rows(bytecols.decimal(values)) == [str(v) for v in values.tolist()]
    want = [f"{v & 0xFFFFFFFFFFFFFFFF:X}" for v in values.tolist()]
    assert _rows(bytecols.hex_upper(values)) == want


def test_split_rows_keeps_non_ascii_text() -> None:
    texts = ["Gerätename", "", "plain", "Δt ≤ 5 ms"]
    table = bytecols.padded_table([t.encode() for t in texts])
    assert _rows(table) == texts
