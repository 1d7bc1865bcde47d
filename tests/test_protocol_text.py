"""One text per fact: the columnar builders say what their scalar twins say."""

from __future__ import annotations

import numpy as np

from cananalyze.columns import bytecols
from cananalyze.protocol import emcy


def test_emcy_text_columns_equal_the_scalar_text():
    rng = np.random.default_rng(3)
    n = 20000
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    data[: n // 4, :2] = 0  # error resets
    data[n // 4 : n // 2, 1] = rng.choice([0x10, 0x21, 0x42, 0x81, 0x82, 0xFF], n // 4)
    dlc = rng.integers(0, 9, n).astype(np.uint8)
    got = bytecols.joined_rows(emcy.text_columns(data, dlc), n)
    want = [emcy.annotation(emcy.fields(bytes(data[i, : dlc[i]]))) for i in range(n)]
    assert got == want


def test_error_classes_equal_error_class_for_every_code():
    codes = np.arange(1 << 16, dtype=np.int64)
    assert emcy.error_classes(codes) == [emcy.error_class(c) for c in codes.tolist()]
    assert emcy.error_classes(np.zeros(0, np.int64)) == []


def test_register_for_sets_generic_and_the_class_bit():
    assert emcy.register_for(0) == 0
    assert emcy.register_names(emcy.register_for(0x8130)) == ["generic", "communication"]
    assert emcy.register_names(emcy.register_for(0x3210)) == ["generic", "voltage"]
    assert emcy.register_names(emcy.register_for(0x6100)) == ["generic"]
