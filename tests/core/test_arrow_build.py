"""arrow_build.strings builds the same Arrow column pyarrow builds from the values."""

from __future__ import annotations

import pyarrow as pa
import pytest

from cananalyze.core.columns.arrow_build import strings

CASES = [
    [],
    [None],
    ["", None, ""],
    ["SDO upload 0x1018:01 Identity object: Vendor-ID = 973 (0x3CD) ok", None, "x"],
    ["temperature 21.5 °C", None, "µs", "plain"],  # non-ASCII: encoded per value
    ["\u2028 line separator", "nul \x00 inside"],
]


@pytest.mark.parametrize("values", CASES)
@pytest.mark.parametrize("large", [False, True])
def test_strings_equal_pyarrow(values: list, large: bool) -> None:
    typ = pa.large_string() if large else pa.string()
    got = strings(values, large=large)
    assert got.type == typ
    assert got.equals(pa.array(values, type=typ))
    assert got.null_count == sum(v is None for v in values)
