"""PDO (CiA 301 7.2.2): columnar decoding, one numpy column per mapped signal, and the text.

Never a loop over frames: all rows given to `decode_pdo` share one COB-ID and one
mapping (the caller splits a batch where the mapping changes). The first 8 data
bytes of each row are read as one little-endian 64-bit word; every mapped object
is then a shift and a mask of that word, which is how CiA 301 packs PDOs
(bit-level, LSB first, no alignment).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cananalyze.protocol.datatypes import DATA_TYPES, DUMMY_INDICES
from cananalyze.protocol.mpdo import text as mpdo_text
from cananalyze.protocol.pdo_map import MapEntry


@dataclass
class PdoColumns:
    """Decoded values per signal name, and which rows could not be decoded.

    Rows flagged `short` (DLC shorter than the mapping) hold 0 / NaN / False in
    every column and must be ignored; `extra` rows (DLC longer) are decoded.
    """

    values: dict[str, np.ndarray] = field(default_factory=dict)
    short: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    extra: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    bytes_needed: int = 0


def _words(data: np.ndarray) -> np.ndarray:
    """(n, 8) uint8 -> n little-endian uint64 words."""
    block = np.ascontiguousarray(data[:, :8], dtype=np.uint8)
    if block.shape[1] < 8:
        block = np.pad(block, ((0, 0), (0, 8 - block.shape[1])))
    return block.view("<u8").reshape(-1)


def _window(long: np.ndarray, offset: int) -> np.ndarray:
    """(n, 64) uint8 payloads -> n little-endian uint64 words of the 64 bits from bit
    `offset` (a CANopen FD PDO's entry, anywhere in its up to 512 bits)."""
    start, shift = offset // 8, offset % 8
    block = np.zeros((long.shape[0], 9), np.uint8)
    part = long[:, start : start + 9]
    block[:, : part.shape[1]] = part
    lo = np.ascontiguousarray(block[:, :8]).view("<u8").reshape(-1)
    if not shift:
        return lo
    hi = block[:, 8].astype(np.uint64)
    return (lo >> np.uint64(shift)) | (hi << np.uint64(64 - shift))


def long_payloads(fb, rows: np.ndarray) -> np.ndarray:
    """(len(rows), 64) uint8: the rows' whole payloads (CAN FD), zero padded."""
    out = np.zeros((len(rows), 64), np.uint8)
    out[:, :8] = fb.data[rows]
    for j, row in enumerate(rows.tolist()):
        extra = fb.long_data.get(row)
        if extra is not None:
            out[j, : len(extra)] = np.frombuffer(extra, np.uint8)
    return out


def _extract(words: np.ndarray, offset: int, bits: int) -> np.ndarray:
    raw = words >> np.uint64(offset)
    if bits < 64:
        raw = raw & np.uint64((1 << bits) - 1)
    return raw


def _column(raw: np.ndarray, entry: MapEntry) -> np.ndarray:
    dtype = DATA_TYPES.get(entry.datatype)
    kind = dtype.kind if dtype is not None else "uint"
    bits = entry.bits
    if kind == "bool":
        return raw != 0
    if kind == "float":
        if bits == 32:  # (a signalling NaN's bits quieten: numpy's warning is no news)
            with np.errstate(invalid="ignore"):
                return raw.astype(np.uint32).view(np.float32).astype(np.float64)
        if bits == 64:
            return raw.view(np.float64)  # raw is _extract's own array: no copy
        kind = "uint"  # a REAL mapped with an odd width cannot be a float: show the bits
    if kind == "int":
        shift = np.uint64(64 - bits)
        return ((raw << shift).view(np.int64)) >> np.int64(64 - bits)
    return raw  # _extract's own array (a shift always makes one): no copy


# an integer or a REAL of 8, 16, 32 bits on a boundary of its own size: read as it lies in
# the words' bytes (a strided view), one conversion instead of a shift, a mask and a sign
# extension; the same numbers (an integer converts exactly, a REAL32 the same way)
_ALIGNED = {
    ("int", 8): "<i1",
    ("int", 16): "<i2",
    ("int", 32): "<i4",
    ("uint", 8): "<u1",
    ("uint", 16): "<u2",
    ("uint", 32): "<u4",
    ("float", 32): "<f4",
}
_WORD = np.dtype("<u8")
_OUT = {"int": np.int64, "uint": np.uint64, "float": np.float64}


def _aligned(words: np.ndarray, offset: int, entry: MapEntry, scaled) -> np.ndarray | None:
    """`_column` of an aligned entry (as float64 when `scaled`), read in one pass; None when
    the entry is not one (`_ALIGNED`) or the words not a contiguous array."""
    bits = entry.bits
    if offset % bits or offset + bits > 64 or words.dtype != _WORD or not words.flags.c_contiguous:
        return None
    dtype = DATA_TYPES.get(entry.datatype)
    kind = dtype.kind if dtype is not None else "uint"
    view = _ALIGNED.get((kind, bits))
    if view is None:
        return None
    lanes = words.view(view).reshape(-1, 64 // bits)[:, offset // bits]
    with np.errstate(invalid="ignore"):  # a REAL32's signalling NaN quietens, as in _column
        return lanes.astype(np.float64 if scaled else _OUT[kind])


def words_of(data: np.ndarray) -> np.ndarray:
    """A batch's (n, 8) uint8 data as n little-endian uint64 words (a view when it can be).

    Gathering one word per PDO row is cheaper than gathering 8 bytes of a 2-D array.
    """
    if data.dtype == np.uint8 and data.ndim == 2 and data.shape[1] == 8 and data.flags.c_contiguous:
        return data.view("<u8").reshape(-1)
    return _words(data)


def decode_pdo(
    data: np.ndarray | None,
    dlc: np.ndarray,
    mapping: list[MapEntry],
    words: np.ndarray | None = None,
    long: np.ndarray | None = None,
) -> PdoColumns:
    """Decode every mapped signal of n PDO frames at once.

    data: (n, 8) uint8 (or `words`: their `words_of`; or `long`: (n, 64) uint8, the whole
    payloads, for a CANopen FD mapping of more than 64 bits); dlc: n byte counts; mapping:
    in PDO order (dummy entries, index 1..7, take space but give no column). Scaled
    signals come out as float64 (value * scale + offset); integers as int64/uint64,
    booleans as bool.
    """
    n = int((data if words is None and long is None else words if long is None else long).shape[0])
    dlc = np.asarray(dlc).astype(np.int64, copy=False)
    total = sum(e.bits for e in mapping)
    needed = (total + 7) // 8
    short = dlc < needed
    extra = dlc > needed
    out = PdoColumns(short=short, extra=extra, bytes_needed=needed)
    if total > 64 and long is None:
        # Classic CAN PDOs carry at most 64 bits; a longer mapping (CANopen FD: up to 512)
        # is decoded from the frames' whole payloads (`long`) only
        out.short = np.ones(n, bool)
        return out
    if words is None and long is None:
        words = _words(data) if n else np.zeros(0, np.uint64)
    any_short = bool(short.any())
    offset = 0
    for entry in mapping:
        if entry.index in DUMMY_INDICES or entry.bits == 0:
            offset += entry.bits
            continue
        scaled = entry.scale is not None or entry.offset
        col = None
        if long is None:
            col = _aligned(words, offset, entry, scaled)
        if col is None:
            if long is not None:
                raw = _extract(_window(long, offset), 0, entry.bits)
            else:
                raw = _extract(words, offset, entry.bits)
            col = _column(raw, entry)
            if scaled:
                col = col.astype(np.float64)
        offset += entry.bits
        if scaled:
            col *= 1.0 if entry.scale is None else entry.scale  # col is this entry's own
            col += entry.offset
        if any_short:
            col = col.copy()
            col[short] = np.nan if col.dtype.kind == "f" else 0
        name = entry.name
        k = 2
        while name in out.values:  # same object mapped twice: keep both
            name = f"{entry.name}_{k}"
            k += 1
        out.values[name] = col
    return out


def annotation(tpdo: bool, number: int, rtr: bool, fields: dict) -> str:
    """'TPDO2  ch1=21.5 degC ch3=20.9 degC': a PDO frame, its decoded signals, its problem."""
    text = f"{'TPDO' if tpdo else 'RPDO'}{number}" + (" remote request" if rtr else "")
    if fields.get("mpdo"):
        text += " " + mpdo_text(fields["mpdo"])
    signals = fields.get("signals")
    if signals:
        text += "  " + signals_text(fields)
    if fields.get("pdo_problem"):
        text += f"  [{fields['pdo_problem']}]"
    return text


def signals_text(fields: dict) -> str:
    """'ch1=21.5 degC mode=3 (running)': a row's signals, units, and the words of a value
    (a DBC's value table, or a CiA 402 statusword/controlword/mode)."""
    units = fields.get("units") or {}
    labels = fields.get("labels") or {}
    words = {k: fields_text(v) for k, v in (fields.get("drive") or {}).items() if v}
    return " ".join(
        _signal_text(k, v, units.get(k), labels.get(k) or words.get(k))
        for k, v in fields["signals"].items()
    )


def fields_text(fields: dict) -> str:
    """A drive value's fields in words (`devices/cia402`: statusword, controlword, mode):
    its state, command or mode, then its flags."""
    head = fields.get("state") or fields.get("command") or fields.get("mode") or ""
    flags = fields.get("flags")
    return f"{head}; {', '.join(flags)}" if flags else head


def _signal_text(name: str, value, unit: str | None, label: str | None = None) -> str:
    if isinstance(value, float):
        value = f"{value:.6g}"
    return f"{name}={value}" + (f" {unit}" if unit else "") + (f" ({label})" if label else "")
