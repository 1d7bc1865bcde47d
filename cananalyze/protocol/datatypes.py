"""CiA 301 basic data types: codes, sizes, and how to turn bytes into values.

Shared by SDO value decoding (scalar, per transaction) and PDO decoding
(columnar, per COB-ID), so both agree on what e.g. INTEGER24 or REAL32 means.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass


@dataclass(frozen=True)
class DataType:
    code: int
    name: str
    bits: int  # 0 = variable length (strings, domain)
    kind: str  # "bool", "int", "uint", "float", "str", "bytes"


_TYPES = [
    DataType(0x01, "BOOLEAN", 1, "bool"),
    DataType(0x02, "INTEGER8", 8, "int"),
    DataType(0x03, "INTEGER16", 16, "int"),
    DataType(0x04, "INTEGER32", 32, "int"),
    DataType(0x05, "UNSIGNED8", 8, "uint"),
    DataType(0x06, "UNSIGNED16", 16, "uint"),
    DataType(0x07, "UNSIGNED32", 32, "uint"),
    DataType(0x08, "REAL32", 32, "float"),
    DataType(0x09, "VISIBLE_STRING", 0, "str"),
    DataType(0x0A, "OCTET_STRING", 0, "bytes"),
    DataType(0x0B, "UNICODE_STRING", 0, "unicode"),
    DataType(0x0C, "TIME_OF_DAY", 48, "bytes"),
    DataType(0x0D, "TIME_DIFFERENCE", 48, "bytes"),
    DataType(0x0F, "DOMAIN", 0, "bytes"),
    DataType(0x10, "INTEGER24", 24, "int"),
    DataType(0x11, "REAL64", 64, "float"),
    DataType(0x12, "INTEGER40", 40, "int"),
    DataType(0x13, "INTEGER48", 48, "int"),
    DataType(0x14, "INTEGER56", 56, "int"),
    DataType(0x15, "INTEGER64", 64, "int"),
    DataType(0x16, "UNSIGNED24", 24, "uint"),
    DataType(0x18, "UNSIGNED40", 40, "uint"),
    DataType(0x19, "UNSIGNED48", 48, "uint"),
    DataType(0x1A, "UNSIGNED56", 56, "uint"),
    DataType(0x1B, "UNSIGNED64", 64, "uint"),
]

DATA_TYPES: dict[int, DataType] = {t.code: t for t in _TYPES}
DATA_TYPES_BY_NAME: dict[str, DataType] = {t.name: t for t in _TYPES}

# Mapping entries that reference these indices are dummy (padding) entries in a PDO.
DUMMY_INDICES = frozenset({0x0001, 0x0002, 0x0003, 0x0004, 0x0005, 0x0006, 0x0007})


def decode_value(data: bytes, code: int) -> int | float | str | bool | None:
    """Scalar value of `data` as CiA 301 type `code` (little-endian).

    Returns None when the type is unknown or the bytes are too short; DOMAIN and
    OCTET_STRING stay bytes-as-hex (the caller shows hex for those).
    """
    dtype = DATA_TYPES.get(code)
    if dtype is None:
        return None
    if dtype.kind == "str":
        return data.split(b"\x00", 1)[0].decode("latin-1")
    if dtype.kind == "unicode":
        return data.decode("utf-16-le", errors="replace").split("\x00", 1)[0]
    if dtype.kind == "bytes":
        return data.hex()
    size = max(1, dtype.bits // 8)
    if len(data) < size:
        return None
    raw = data[:size]
    if dtype.kind == "bool":
        return bool(raw[0] & 1)
    if dtype.kind == "float":
        return struct.unpack("<f" if size == 4 else "<d", raw)[0]
    return int.from_bytes(raw, "little", signed=dtype.kind == "int")


def decode_column(raw, length, code: int) -> list:
    """`decode_value` of many short values of one type at once: a list, one value per row.

    raw: (k, 4) uint8 rows (an expedited SDO's data field), length: bytes used (0..4).
    Integer, boolean and REAL32 values are decoded as numpy columns (the bulk of
    polled objects); strings and the rest go value by value through `decode_value`.
    """
    import numpy as np

    dtype = DATA_TYPES.get(code)
    k = len(raw)
    if dtype is None:
        return [None] * k
    size = max(1, dtype.bits // 8)
    if dtype.kind in ("int", "uint", "bool") or (dtype.kind == "float" and size == 4):
        if size > 4:
            return [None] * k  # never fits in an expedited transfer's 4 bytes
        word = np.ascontiguousarray(raw, np.uint8).view("<u4").ravel()
        if dtype.kind == "float":
            out = word.view("<f4").tolist()
        elif dtype.kind == "bool":
            out = ((word & 1) != 0).tolist()
        else:
            out = _ints(word, dtype.kind, size).tolist()
        short = np.flatnonzero(np.asarray(length) < size).tolist()
        for i in short:
            out[i] = None
        return out
    return [
        decode_value(bytes(r[:n]), code)
        for r, n in zip(
            np.asarray(raw, np.uint8).tolist(), np.asarray(length).tolist(), strict=True
        )
    ]


def _ints(word, kind: str, size: int):
    import numpy as np

    v = (word & np.uint32((1 << (8 * size)) - 1)).astype(np.int64)
    if kind == "int":
        v = np.where(v >= 1 << (8 * size - 1), v - (1 << (8 * size)), v)
    return v


def decode_int_column(raw, length, code: int):
    """`decode_column`'s integers as numpy: (int64 values, bool mask of the None ones).

    None when the type is not an integer that fits in 4 bytes (then decode_column
    gives bools, floats, texts or None). Lets the table export keep numbers as numbers.
    """
    import numpy as np

    dtype = DATA_TYPES.get(code)
    if dtype is None or dtype.kind not in ("int", "uint"):
        return None
    size = max(1, dtype.bits // 8)
    if size > 4:
        return None
    word = np.ascontiguousarray(raw, np.uint8).view("<u4").ravel()
    return _ints(word, dtype.kind, size), np.asarray(length) < size
