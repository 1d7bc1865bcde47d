"""Columnar PDO decoding: bit-level edge cases with hand-computed values, and a
cross-check against cantools decoding a real log with its author's DBC."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import real_file

from cananalyze.protocol.pdo import decode_pdo
from cananalyze.protocol.pdo_map import MapEntry

U8, U16, U32, I16, I32, REAL32, REAL64, I24, U64, I64, BOOL = (
    0x05,
    0x06,
    0x07,
    0x03,
    0x04,
    0x08,
    0x11,
    0x10,
    0x1B,
    0x15,
    0x01,
)


def frames(*rows: bytes) -> tuple[np.ndarray, np.ndarray]:
    data = np.zeros((len(rows), 8), np.uint8)
    for i, r in enumerate(rows):
        data[i, : len(r)] = list(r)
    return data, np.array([len(r) for r in rows], np.uint8)


def test_unaligned_fields_and_signed_24_bit():
    mapping = [
        MapEntry(0x2000, 1, 3, "u3", U8),
        MapEntry(0x2000, 2, 5, "i5", 0x02),
        MapEntry(0x2000, 3, 1, "flag", BOOL),
        MapEntry(0x2000, 4, 7, "u7", U8),
        MapEntry(0x2000, 5, 24, "i24", I24),
    ]
    # 0xAD = 101 01101b: bits 0-2 = 0b101 = 5; bits 3-7 = 0b10101 = 21 -> 21 - 32 = -11
    # 0x7F: bit 8 = 1 -> True; bits 9-15 = 0x3F = 63
    # FE FF 80 little-endian = 0x80FFFE -> 0x80FFFE - 0x1000000 = -8323074
    # second row: 0x7FFFFF is the largest INTEGER24, 0x00 bit 8 False
    data, dlc = frames(bytes([0xAD, 0x7F, 0xFE, 0xFF, 0x80]), bytes([0x00, 0x00, 0xFF, 0xFF, 0x7F]))
    out = decode_pdo(data, dlc, mapping)
    assert out.values["u3"].tolist() == [5, 0]
    assert out.values["i5"].tolist() == [-11, 0]
    assert out.values["flag"].dtype == bool
    assert out.values["flag"].tolist() == [True, False]
    assert out.values["u7"].tolist() == [63, 0]
    assert out.values["i24"].tolist() == [-8323074, 8388607]
    assert out.values["i24"].dtype == np.int64
    assert out.values["u7"].dtype == np.uint64
    assert not out.short.any() and not out.extra.any()


def test_real32_unaligned_and_real64():
    m32 = [MapEntry(0x2000, 1, 8, "b", U8), MapEntry(0x2000, 2, 32, "f", REAL32)]
    # 1.5f = 0x3FC00000, -2.25f = 0xC0100000, stored LSB first after one byte
    data, dlc = frames(bytes([7, 0, 0, 0xC0, 0x3F]), bytes([9, 0, 0, 0x10, 0xC0]))
    out = decode_pdo(data, dlc, m32)
    assert out.values["b"].tolist() == [7, 9]
    assert out.values["f"].tolist() == [1.5, -2.25]
    m64 = [MapEntry(0x2000, 3, 64, "d", REAL64)]
    # 0.1 as IEEE double is 0x3FB999999999999A
    data, dlc = frames(bytes([0x9A, 0x99, 0x99, 0x99, 0x99, 0x99, 0xB9, 0x3F]))
    assert decode_pdo(data, dlc, m64).values["d"].tolist() == [0.1]


def test_64_bit_integers():
    data, dlc = frames(bytes([0xFF] * 8))
    assert decode_pdo(data, dlc, [MapEntry(0x2000, 1, 64, "u", U64)]).values["u"].tolist() == [
        0xFFFFFFFFFFFFFFFF
    ]
    assert decode_pdo(data, dlc, [MapEntry(0x2000, 1, 64, "i", I64)]).values["i"].tolist() == [-1]


def test_short_and_long_dlc():
    mapping = [MapEntry(0x2000, 1, 16, "a", U16), MapEntry(0x2000, 2, 16, "b", I16)]
    data, dlc = frames(bytes([1, 0, 0xFE, 0xFF]), bytes([1, 0, 2]), bytes([3, 0, 4, 0, 9, 9, 9, 9]))
    out = decode_pdo(data, dlc, mapping)
    assert out.short.tolist() == [False, True, False]
    assert out.extra.tolist() == [False, False, True]
    assert out.values["a"].tolist() == [1, 0, 3]  # short row is not decoded
    assert out.values["b"].tolist() == [-2, 0, 4]
    assert out.bytes_needed == 4


def test_dummy_entries_take_space_but_give_no_column():
    mapping = [
        MapEntry(0x2000, 1, 8, "a", U8),
        MapEntry(0x0005, 0, 8, "dummy", U8),
        MapEntry(0x2000, 2, 8, "c", U8),
    ]
    data, dlc = frames(bytes([1, 2, 3]))
    out = decode_pdo(data, dlc, mapping)
    assert list(out.values) == ["a", "c"]
    assert out.values["c"].tolist() == [3]


def test_scaling_gives_float_and_duplicates_keep_both():
    mapping = [
        MapEntry(0x6401, 1, 16, "t", I16, "°C", 0.1),
        MapEntry(0x6401, 1, 16, "t", I16, "°C", 0.1),
    ]
    data, dlc = frames(bytes([0x0C, 0xFE, 0xE8, 0x03]))  # -500, 1000
    out = decode_pdo(data, dlc, mapping)
    assert out.values["t"].dtype == np.float64
    assert out.values["t"].tolist() == pytest.approx([-50.0])
    assert out.values["t_2"].tolist() == pytest.approx([100.0])


# struct's reading of one aligned object, and its type code, per (format, bits)
_ALIGNED_TYPES = [
    ("<b", 8, 0x02),
    ("<h", 16, I16),
    ("<i", 32, I32),
    ("<B", 8, U8),
    ("<H", 16, U16),
    ("<I", 32, U32),
    ("<f", 32, REAL32),
]


@pytest.mark.parametrize("fmt,bits,code", _ALIGNED_TYPES)
@pytest.mark.parametrize("scaled", [False, True])
def test_aligned_objects_read_as_struct_reads_them(fmt, bits, code, scaled):
    """An 8/16/32-bit object on its own boundary is read in one pass (`pdo._aligned`): the
    same numbers and dtypes as struct unpacking each frame, and as the shift-and-mask path
    (taken for words that are not one contiguous array), short rows 0 / NaN."""
    import struct

    rng = np.random.default_rng(bits * 7 + code)
    data = rng.integers(0, 256, (300, 8), dtype=np.uint8)
    data[:4] = [0x00, 0x00, 0xC0, 0x7F, 0x00, 0x00, 0x80, 0xFF]  # REAL32 NaN, -inf
    dlc = np.full(300, 8, np.uint8)
    dlc[5] = 7  # short: not decoded
    scale, off = (0.25, -3.0) if scaled else (None, 0.0)
    mapping = [
        MapEntry(0x2000, k, bits, f"v{k}", code, None, scale, off) for k in range(64 // bits)
    ]
    words = np.ascontiguousarray(data).view("<u8").reshape(-1)
    fast = decode_pdo(None, dlc, mapping, words=words)
    spread = np.zeros(600, np.uint64)
    spread[::2] = words
    slow = decode_pdo(None, dlc, mapping, words=spread[::2])  # not contiguous: shift and mask
    for k, e in enumerate(mapping):
        got, ref = fast.values[e.name], slow.values[e.name]
        assert got.dtype == ref.dtype
        assert got.dtype == (np.float64 if scaled or fmt == "<f" else ref.dtype)
        assert np.array_equal(got.view(np.uint64), ref.view(np.uint64))  # NaN bits too
        want = [struct.unpack_from(fmt, bytes(row), k * bits // 8)[0] for row in data]
        want = np.array(want, np.float64 if scaled or fmt == "<f" else got.dtype)
        if scaled:
            want = want * scale + off
        want[5] = np.nan if want.dtype.kind == "f" else 0  # short: every column
        np.testing.assert_array_equal(got, want)


def test_empty_batch():
    data = np.zeros((0, 8), np.uint8)
    out = decode_pdo(data, np.zeros(0, np.uint8), [MapEntry(0x2000, 1, 8, "a", U8)])
    assert out.values["a"].shape == (0,)


def _read_candump(path, limit):
    """(can_id, data) of the first `limit` frames of a `candump -l` log."""
    rows = []
    with open(path) as fh:
        for line in fh:
            parts = line.split()
            if len(parts) != 3 or "#" not in parts[2]:
                continue
            ident, payload = parts[2].split("#", 1)
            rows.append((int(ident, 16), bytes.fromhex(payload)))
            if len(rows) >= limit:
                break
    return rows


def test_matches_cantools_on_real_axiomatic_log():
    import cantools
    import yaml

    from cananalyze.devices.profile import load_eds

    folder = "calumroy__CANopen_socketCAN_Test/"
    log = real_file(folder + "can_log_070825_brake_sensor_test1.log")
    db = cantools.database.load_file(str(real_file(folder + "axiomatic_23123-1.dbc")))
    config = yaml.safe_load(real_file(folder + "test_axiomatic.yaml").read_text())
    profile = load_eds(real_file(folder + "EDS-23123-1.01.eds"))
    node = config["axio_dev"][0]["device_id"]
    entries = {e["name"]: e for e in config["axio_dev"][0]["object_dict_config"]}
    rows = _read_candump(log, 3000)
    checked = 0
    for number in range(3):
        words = [
            s["value"]
            for s in entries[f"Transmit PDO Mapping Parameter {number}"]["subindicies"][1:]
        ]
        mapping = []
        for w in words:
            mapping += profile.map_entries(w >> 16, (w >> 8) & 0xFF, w & 0xFF)
        cob = 0x180 + 0x100 * number + node
        sel = [d for i, d in rows if i == cob]
        assert len(sel) > 100
        data, dlc = frames(*sel)
        out = decode_pdo(data, dlc, mapping)
        assert not out.short.any()
        message = db.get_message_by_frame_id(cob)
        expect = [message.decode(d, scaling=False) for d in sel]
        for entry, signal in zip(mapping, message.signals, strict=True):
            got = out.values[entry.name]
            want = np.array([e[signal.name] for e in expect])
            if signal.is_signed == (got.dtype.kind == "i"):
                assert got.tolist() == want.tolist(), signal.name
            else:  # DBC and EDS disagree on signedness (input11_freq): same bits
                assert (got.astype(np.int64) & 0xFFFF).tolist() == (want & 0xFFFF).tolist()
            checked += len(sel)
    assert checked > 1000
