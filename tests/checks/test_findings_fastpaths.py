"""The findings' column-wise paths give exactly what their per-value twins give.

EMCY texts as byte columns (`error_lines`, `code_texts`) against `error_text` and
`register_text`; `rounded6` against Python's `round`; the findings table's
conversions from arrays and known types against the list path; the event rows'
"[rule] message" by object add against the format per row.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from cananalyze.core.finding_columns import FindingColumns, round6, rounded6
from cananalyze.decode.events.build import finding_event_columns
from cananalyze.outputs.tables import pandas_like as pl
from cananalyze.protocol.emcy import (
    ERROR_CLASSES,
    code_texts,
    error_lines,
    error_text,
    register_text,
)


def _lines(codes, regs) -> list[str]:
    return [f"EMCY {error_text(c)}; {register_text(r)}" for c, r in zip(codes, regs, strict=True)]


@pytest.mark.parametrize("seed", range(6))
def test_error_lines_random(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(0, 3000))
    codes = rng.integers(0, 0x10000, n)
    regs = rng.integers(0, 0x100, n)
    got = error_lines(codes, regs)
    assert got.dtype == object and got.shape == (n,)
    assert got.tolist() == _lines(codes.tolist(), regs.tolist())
    assert all(type(x) is str for x in got.tolist())
    assert code_texts(codes) == [f"0x{c:04X}" for c in codes.tolist()]


def test_error_lines_every_class_and_edge():
    keys = sorted(ERROR_CLASSES)
    codes = [*keys, *(k + 1 for k in keys), *(k | 0xF for k in keys), *(k | 0xFF for k in keys)]
    codes += [0, 1, 0xFFFF, 0x0FFF, 0x8FFF, 0xFF00, 0xEFFF]
    regs = [i % 256 for i in range(len(codes))]
    assert error_lines(np.array(codes), np.array(regs)).tolist() == _lines(codes, regs)
    assert error_lines(np.zeros(0, np.int64), np.zeros(0, np.int64)).tolist() == []
    assert code_texts(np.zeros(0, np.int64)) == []


def test_rounded6_matches_round():
    rng = np.random.default_rng(1)
    halves = (np.arange(-2000, 2000) + 0.5) / 1e6  # within rounding error of a half
    x = np.concatenate(
        [rng.normal(0, 1e3, 5000), halves, [0.0, -0.0, 1e300, -1e300, 2.0**60, np.nan]]
    )
    got = rounded6(x)
    for v, g in zip(x.tolist(), got.tolist(), strict=True):
        if v != v:
            assert g != g
        else:
            assert g == round(v, 6)
    assert round6(x)[-1] is None
    assert round6(x)[:-1] == got[:-1].tolist()


def _same(a: pa.Array, b: pa.Array) -> None:
    assert a.type == b.type and a.equals(b)


@pytest.mark.parametrize("how", ["float", "text", "large", "string", "null"])
def test_convert_float_array_as_its_list(how):
    x = np.array([1.5, np.nan, -3.0, 1e-7])
    _same(pl.convert(x, how), pl.convert(x.tolist(), how))


@pytest.mark.parametrize("how", ["large", "string"])
def test_convert_known_str(how):
    values = ["a", "", "é", "xyz" * 50]
    _same(pl.convert(values, how, {str}), pl.convert(values, how))
    mixed = ["a", None, 3]
    _same(pl.convert(mixed, how, {str, type(None), int}), pl.convert(mixed, how))


def _block(rule, messages, t=None) -> FindingColumns:
    n = len(messages)
    t = np.arange(n, dtype=np.float64) if t is None else t
    out = FindingColumns.block(rule, "warning", t, 5, 0x85, list(messages), "m", "e", "why")
    out.t_rel = t - 0.25
    return out


@pytest.mark.parametrize(
    "rule,messages",
    [
        ("emcy", ["EMCY 0x1000 Generic error", "x", "é"]),
        ("emcy", ["a", "", "b"]),  # an empty message: the format per row
        ("", ["a", "b"]),
    ],
)
def test_finding_event_rows(rule, messages):
    found = _block(rule, messages)
    ev = finding_event_columns(found, 10)
    want = [
        f"[{r}] {m}" if r and m else str(m or r or "finding")
        for r, m in zip([rule] * len(messages), messages, strict=True)
    ]
    assert ev.message.tolist() == want
    assert ev.t.tolist() == found.t.tolist() and ev.t is not found.t
    assert ev.row.tolist() == (found.row + 10).tolist()
