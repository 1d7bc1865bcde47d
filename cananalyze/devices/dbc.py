"""DBC files (`--dbc FILE`): cantools reads them, the frames are decoded as columns.

cantools parses the file and gives each signal's layout (start bit, length, byte
order, sign, scale, offset, unit, value table, multiplexer). Its `decode_message`
builds one dict per frame, which a long log cannot afford; the same layout is a
shift and a mask of the frame's 8 bytes read as one 64-bit word (little-endian for
Intel signals, big-endian for Motorola ones), like `protocol/pdo.py` does for PDOs.
Messages of more than 8 bytes (CAN FD) go through cantools frame by frame: rare.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cananalyze.core.errors import InputError
from cananalyze.core.text import printable


@dataclass(frozen=True)
class DbcSignal:
    """One signal's layout, as cantools gives it, reduced to what the word shift needs."""

    name: str
    shift: int  # position of the signal's least significant bit in the 64-bit word
    bits: int
    big_endian: bool
    signed: bool
    is_float: bool
    scale: float
    offset: float
    unit: str | None
    choices: dict[int, str] = field(default_factory=dict)
    mux_ids: tuple[int, ...] | None = None  # shown only when the multiplexer has one of these


@dataclass(frozen=True)
class DbcMessage:
    frame_id: int
    extended: bool
    name: str
    length: int
    bytes_needed: int  # bytes the signals reach into; a shorter frame is not decoded
    signals: tuple[DbcSignal, ...]
    multiplexer: str | None  # the multiplexer signal's name (one level)
    source: object = field(repr=False, compare=False, default=None)  # the cantools Message
    columnar: bool = True  # False: decoded by cantools per frame (CAN FD, nested multiplexing)


def _layout(sig) -> tuple[int, bool]:
    """(shift, big_endian) of a cantools signal in the frame's 64-bit word.

    Intel: the DBC start bit is the LSB, bit k of the little-endian word. Motorola: the
    start bit names the MSB as bit (start % 8) of byte (start // 8); in the big-endian
    word that byte is the (7 - start // 8)-th from the bottom.
    """
    if sig.byte_order == "little_endian":
        return sig.start, False
    msb = (7 - sig.start // 8) * 8 + sig.start % 8
    return msb - sig.length + 1, True


def _message(msg) -> DbcMessage:
    signals = []
    columnar = msg.length <= 8
    mux_names = [printable(s.name) for s in msg.signals if s.is_multiplexer]
    if len(mux_names) > 1:
        columnar = False  # nested multiplexing: cantools decides per frame
    needed = 0
    for sig in msg.signals:
        shift, big = _layout(sig)
        if shift < 0 or shift + sig.length > 64:
            columnar = False
        # bytes reached: an Intel signal's top bit, a Motorola signal's LSB byte
        reach = (shift + sig.length + 7) // 8 if not big else 8 - max(shift, 0) // 8
        needed = max(needed, reach)
        choices = {int(k): printable(str(v)) for k, v in (sig.choices or {}).items()}
        mux = sig.multiplexer_ids
        signals.append(
            DbcSignal(
                name=printable(sig.name),  # a DBC's texts, as a terminal may show them
                shift=shift,
                bits=sig.length,
                big_endian=big,
                signed=bool(sig.is_signed),
                is_float=bool(sig.is_float),
                scale=float(sig.scale),
                offset=float(sig.offset),
                unit=printable(sig.unit) if sig.unit else None,
                choices=choices,
                mux_ids=tuple(int(m) for m in mux) if mux else None,
            )
        )
    return DbcMessage(
        frame_id=int(msg.frame_id),
        extended=bool(msg.is_extended_frame),
        name=printable(msg.name),
        length=int(msg.length),
        bytes_needed=min(needed, msg.length) if columnar else msg.length,
        signals=tuple(signals),
        multiplexer=mux_names[0] if mux_names else None,
        source=msg,
        columnar=columnar,
    )


@dataclass
class DbcSet:
    """The messages of one or more DBC files; a later file's message replaces an earlier one's."""

    messages: dict[tuple[int, bool], DbcMessage] = field(default_factory=dict)  # (id, extended)
    files: list[str] = field(default_factory=list)

    @property
    def standard_ids(self) -> set[int]:
        return {i for i, ext in self.messages if not ext}

    def __bool__(self) -> bool:
        return bool(self.messages)


def load_dbc(paths: Iterable[str | Path]) -> DbcSet:
    """Read DBC files with cantools; a file that does not parse is one InputError naming
    it and cantools' reason."""
    import cantools

    out = DbcSet()
    for path in paths:
        try:
            db = cantools.database.load_file(str(path), database_format="dbc", strict=False)
        except FileNotFoundError:
            raise InputError(f"{path}: no such DBC file") from None
        except OSError as exc:
            raise InputError(f"{path}: cannot read the DBC file: {exc.strerror or exc}") from None
        except Exception as exc:  # cantools raises ParseError, UnsupportedDatabaseFormatError
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise InputError(f"{path}: not a DBC file cantools can read: {reason}") from None
        for msg in db.messages:
            m = _message(msg)
            out.messages[(m.frame_id, m.extended)] = m
        out.files.append(str(path))
    return out


# --- decoding ------------------------------------------------------------------------


def _raw(le: np.ndarray, be: np.ndarray | None, sig: DbcSignal) -> np.ndarray:
    word = be if sig.big_endian else le
    raw = word >> np.uint64(sig.shift)
    if sig.bits < 64:
        raw = raw & np.uint64((1 << sig.bits) - 1)
    return raw


def _value(raw: np.ndarray, sig: DbcSignal) -> np.ndarray:
    if sig.is_float:
        if sig.bits == 32:
            col = raw.astype(np.uint32).view(np.float32).astype(np.float64)
        else:
            col = raw.view(np.float64).copy()
    elif sig.signed:
        shift = np.uint64(64 - sig.bits)
        col = ((raw << shift).view(np.int64)) >> np.int64(64 - sig.bits)
    else:
        col = raw.copy()
    if sig.is_float or sig.scale != 1.0 or sig.offset != 0.0:
        return col.astype(np.float64) * sig.scale + sig.offset
    return col.astype(np.int64) if col.dtype == np.uint64 and sig.bits < 64 else col


def decode_columns(msg: DbcMessage, data: np.ndarray) -> dict[str, np.ndarray]:
    """Every signal of n frames of one message at once: (n, 8) uint8 data -> columns.

    Scaled signals are float64 (raw * scale + offset, as cantools gives them), unscaled
    integers int64. A multiplexed signal is NaN in rows whose multiplexer names another.
    """
    block = np.ascontiguousarray(data[:, :8], dtype=np.uint8)
    le = block.view("<u8").reshape(-1)
    be = (
        block.view(">u8").reshape(-1).astype(np.uint64)
        if any(s.big_endian for s in msg.signals)
        else None
    )
    out: dict[str, np.ndarray] = {}
    mux_value = None
    if msg.multiplexer is not None:
        mux_sig = next(s for s in msg.signals if s.name == msg.multiplexer)
        mux_value = _raw(le, be, mux_sig).astype(np.int64)
    for sig in msg.signals:
        col = _value(_raw(le, be, sig), sig)
        if sig.mux_ids is not None and mux_value is not None:
            col = col.astype(np.float64)
            col[~np.isin(mux_value, np.array(sig.mux_ids, np.int64))] = np.nan
        out[sig.name] = col
    return out


def decode_rows(msg: DbcMessage, payloads: list[bytes]) -> dict[str, np.ndarray]:
    """The frames cantools decodes one by one (CAN FD, nested multiplexing): as columns."""
    names = [s.name for s in msg.signals]
    cols = {name: np.full(len(payloads), np.nan) for name in names}
    # cantools' names are the file's; ours are printable (the same but control characters)
    ours = dict(zip((s.name for s in msg.source.signals), names, strict=True))
    for i, data in enumerate(payloads):
        try:
            values = msg.source.decode(data, decode_choices=False, allow_truncated=True)
        except Exception:  # a frame cantools refuses stays NaN
            continue
        for name, v in values.items():
            name = ours.get(name, name)
            if name in cols and isinstance(v, (int, float)):
                cols[name][i] = v
    return cols
