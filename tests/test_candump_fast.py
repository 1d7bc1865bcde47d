"""The fixed-layout candump shortcut gives exactly the general bulk parser's columns.

Lines are fuzzed around the common layout (other widths, interfaces, ids, data
lengths, direction flags, RTR, CAN FD, stray bytes), so both the rows the
shortcut takes and the rows it must leave to the general parser are exercised.
"""

from __future__ import annotations

import random

import numpy as np
import pytest

from cananalyze.io import candump, candump_fast

_HEXCH = "0123456789abcdefABCDEF"


def _line(rng: random.Random) -> str:
    ni = 10 if rng.random() < 0.8 else rng.choice([1, 3, 9, 11, 16])
    nf = 6 if rng.random() < 0.8 else rng.choice([3, 9, 1])
    t = (
        "".join(rng.choice("0123456789") for _ in range(ni))
        + "."
        + "".join(rng.choice("0123456789") for _ in range(nf))
    )
    ch = (
        "can0"
        if rng.random() < 0.8
        else rng.choice(["can1", "vcan10", "a-very-long-interface-name0"])
    )
    ident = "".join(rng.choice(_HEXCH) for _ in range(rng.choice([3, 3, 3, 8, 8, 2, 5])))
    if rng.random() < 0.05:
        ident = "2" + ident[1:]  # 29-bit with the error flag when 8 digits
    n = rng.choice([0, 1, 2, 4, 7, 8, 8, 8, 9])
    data = "".join(rng.choice(_HEXCH) for _ in range(2 * n))
    kind = rng.random()
    if kind < 0.04:
        data = "R" + rng.choice(["", "3", "8", "9"])
    elif kind < 0.07:
        data = "#" + rng.choice("0123") + data
    line = f"({t}) {ch} {ident}#{data}"
    if rng.random() < 0.3:
        line += rng.choice([" R", " T", " X", " ", "  T"])
    if rng.random() < 0.08:  # one stray byte anywhere
        i = rng.randrange(len(line) + 1)
        line = line[:i] + rng.choice(" #().xZ\t0") + line[i + 1 :]
    return line


def _cols(parse, text: bytes):
    arr = np.frombuffer(text + bytes(candump.PAD), np.uint8)
    nl = np.flatnonzero(arr[: len(text)] == 10)
    starts = np.r_[0, nl[:-1] + 1].astype(np.int64)
    ends = nl.astype(np.int64)
    chans = candump._Channels()
    cols, slow = parse(arr, starts, ends, chans)
    return cols, slow, chans.names


@pytest.mark.parametrize("seed", range(6))
def test_shortcut_equals_general_parser(seed: int) -> None:
    rng = random.Random(seed)
    lines = [_line(rng) for _ in range(4000)]
    lines[seed % 2] = "(1767225600.000000) can0 181#00"  # the layout the shortcut takes
    if seed % 2:
        lines[0] = lines[0].replace("(", "x", 1)  # first line not a log line: layout from the next
    text = ("\n".join(lines) + "\n").encode()
    ref, ref_slow, ref_names = _cols(candump._bulk_log_lines, text)
    got, got_slow, got_names = _cols(candump._log_lines, text)
    assert got_slow.tolist() == ref_slow.tolist()
    good = ~ref_slow
    lay = candump_fast.Layout.of(lines[seed % 2].encode())
    arr = np.frombuffer(text + bytes(candump.PAD), np.uint8)
    nl = np.flatnonzero(arr[: len(text)] == 10)
    _, fits = candump_fast.parse(arr, candump_fast.words(arr), np.r_[0, nl[:-1] + 1], nl, lay)
    assert fits.sum() > 500 and (good & ~fits).sum() > 200  # both paths exercised
    for name, a, b in zip(
        ("t", "can_id", "flags", "dlc", "data", "channel"), got, ref, strict=True
    ):
        if name == "channel":
            a, b = np.array(got_names)[a[good]], np.array(ref_names)[b[good]]
            assert a.tolist() == b.tolist(), name
        else:
            assert a[good].tolist() == b[good].tolist(), name


def test_fields_decode() -> None:
    text = b"(1767225600.000100) can0 18FF00A1#DEADbeef0102 T\n"
    arr = np.frombuffer(text + bytes(candump.PAD), np.uint8)
    lay = candump_fast.Layout.of(text.rstrip())
    cols, fits = candump_fast.parse(
        arr, candump_fast.words(arr), np.array([0]), np.array([len(text) - 1]), lay
    )
    t, can_id, flags, dlc, data = cols
    assert fits.tolist() == [True]
    assert t[0] == 1767225600.0001 and can_id[0] == 0x18FF00A1 and dlc[0] == 6
    assert data[0].tolist() == [0xDE, 0xAD, 0xBE, 0xEF, 0x01, 0x02, 0, 0]
