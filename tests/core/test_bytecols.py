"""Text built column-wise (`bytecols`) equals Python's own formatting."""

from __future__ import annotations

import numpy as np

from cananalyze.core.columns import bytecols

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


def test_small_decimals_by_table_equal_python() -> None:
    """Values in 0..65535 (identifiers, lengths, node-IDs) come from a table: the same
    text, and the same matrix width (a sign column and the largest value's digits)."""
    rng = np.random.default_rng(4)
    for top in (1, 9, 10, 127, 2047, 65535):
        values = np.array([0, top, *rng.integers(0, top + 1, 500).tolist()], np.int64)
        got = bytecols.decimal(values)
        assert _rows(got) == [str(v) for v in values.tolist()]
        assert got.shape == (values.size, 1 + len(str(top)))
        assert (got[:, 0] == bytecols.PAD).all()
    assert _rows(bytecols.decimal(np.array([65536, 3]))) == ["65536", "3"]  # past the table


def test_digits_equal_python_zero_padded() -> None:
    """Both of digits' word sizes: values that fit in 32 bits, and the 64-bit rest."""
    rng = np.random.default_rng(5)
    for top in (10**6, 2**32 - 1, 2**32, 2**63 - 1):
        values = np.array([0, 9, 10, top, *rng.integers(0, top, 500).tolist()], np.int64)
        width = len(str(top))
        want = [f"{v:0{width}d}" for v in values.tolist()]
        assert _rows(bytecols.digits(values, width)) == want


def test_no_columns_give_no_bytes() -> None:
    """A batch with no row shown has no columns (every decode's last, empty batch):
    empty rows, not a numpy error."""
    for n in (0, 3):
        blob, ends = bytecols.compact([], n, True)
        assert blob == b"" and ends.tolist() == [0] * n
        assert bytecols.compact([], n, False) == (b"", None)
    assert bytecols.joined_rows([], 2) == ["", ""]


def test_split_rows_keeps_non_ascii_text() -> None:
    texts = ["Gerätename", "", "plain", "Δt ≤ 5 ms"]
    table = bytecols.padded_table([t.encode() for t in texts])
    assert _rows(table) == texts


def _pairs(rng: np.random.Generator, m: int):
    """m expedited SDO pairs (uploads and downloads, 1-4 bytes, some aborted) as frames."""
    from cananalyze.core.frames import FrameBatch

    fb = FrameBatch.allocate(2 * m, ("can0",))
    fb.t[:] = np.arange(2 * m) * 0.001
    fb.dlc[:] = 8
    node = rng.integers(1, 5, m)
    index = rng.choice([0x2000, 0x2001, 0x2002, 0x6000], m)
    sub = rng.integers(0, 3, m)
    size = rng.integers(1, 5, m)
    upload = rng.random(m) < 0.6
    value = rng.integers(0, 256, (m, 4), dtype=np.uint8)
    value[rng.random(m) < 0.3] = 0xFF  # negative as signed, large as unsigned
    value[rng.random(m) < 0.2] = 0  # small values print without hex
    for k in range(m):
        req, resp = fb.data[2 * k], fb.data[2 * k + 1]
        fb.can_id[2 * k], fb.can_id[2 * k + 1] = 0x600 + node[k], 0x580 + node[k]
        for d in (req, resp):
            d[1:4] = (index[k] & 0xFF, index[k] >> 8, sub[k])
        code = 0x43 | ((4 - size[k]) << 2)  # expedited, size given
        if upload[k]:
            req[0], resp[0] = 0x40, code
            resp[4:8] = value[k]
        else:
            req[0], resp[0] = code - 0x20, 0x60
            req[4:8] = value[k]
        if rng.random() < 0.05:
            resp[0], resp[4:8] = 0x80, (0x00, 0x00, 0x02, 0x06)  # object does not exist
    return fb, np.arange(0, 2 * m, 2), np.arange(1, 2 * m, 2)


def test_sdo_messages_equal_the_per_record_text() -> None:
    """Integer values of every sign and size, unknown objects (data only), aborts, names
    with non-ASCII letters: the columns say what `sdo_message` says of each record."""
    from cananalyze.decode.events.sdo_text import sdo_message, sdo_messages
    from cananalyze.decode.sdo import fastpath

    # INTEGER8/16/32 and UNSIGNED32; 0x6000 unknown (no name, no type: data only)
    types = {0x2000: ("Drehzahl", 0x0002), 0x2001: ("Temp", 0x0003), 0x2002: ("Zähler", 0x0007)}

    def info(node: int, index: int, sub: int):
        if index not in types:
            return None
        name, code = types[index]
        return (f"{name} {sub}", 0x0004 if sub == 2 else code)

    rng = np.random.default_rng(11)
    for lookup in (info, None):
        fb, a, b = _pairs(rng, 600)
        fields = fastpath.pair_record_columns(fb, a, b, lookup)
        got = sdo_messages(fields)
        assert got is not None  # every decoded value is an integer
        want = []
        for j in range(len(fields)):
            r = fields.record(j)
            want.append(
                sdo_message(
                    r["direction"], r["index"], r["subindex"], r["name"], r["result"],
                    r["value"], r["data"], r["abort_text"], r["detail"],
                )
            )  # fmt: skip
        assert got == want
        if lookup is not None:  # negative, small and wide integers, and data only
            assert all(any(p in x for x in want) for p in (" = -", "(0x", " = 0 ok", " data "))
        else:  # no object known: every value is data
            assert all(" = " not in x for x in want) and any(" data " in x for x in want)
        assert fields.held


def test_joined_rows_with_a_separator_inside_a_text() -> None:
    texts = ["a\x1fb", "plain", "", "ü\x1f"]
    table = bytecols.padded_table([t.encode() for t in texts])
    assert bytecols.joined_rows([table], len(texts)) == texts
    assert bytecols.joined_rows([table[1:3]], 2) == ["plain", ""]


def test_hex_bytes_equal_bytes_hex() -> None:
    rng = np.random.default_rng(4)
    raw = rng.integers(0, 256, (500, 4), dtype=np.uint8)
    length = rng.integers(0, 5, 500)
    want = [bytes(r[:k]).hex() for r, k in zip(raw, length, strict=True)]
    assert _rows(bytecols.hex_bytes(raw, length)) == want
