"""Device knowledge an EDS cannot hold, read from `decoders/<key>.toml`.

An EDS says which objects exist and what the default PDOs carry, but not that a
byte of digital inputs is eight switches, that a value is in tenths of a degree
when object 0x2107 says "Pt100", or what a vendor's EMCY bytes mean. The sidecar
says that, as data, so adding a device needs no code.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from cananalyze.core.errors import InputError


@dataclass(frozen=True)
class SignalSpec:
    """How to show one mapped object: name, unit, scale, or a split into booleans."""

    name: str
    unit: str | None = None
    scale: float | None = None
    offset: float = 0.0
    split: tuple[str, ...] = ()  # one boolean per bit, LSB first
    unit_table: str | None = None  # units chosen by the value of a context object
    context: tuple[int, int] | None = None  # (index, subindex) of that object


@dataclass(frozen=True)
class UnitChoice:
    unit: str | None
    scale: float | None
    offset: float = 0.0
    label: str = ""


@dataclass
class EmcySpec:
    """Manufacturer-specific EMCY bytes: fields, flag bits and known meanings."""

    fields: list[tuple[str, int, int]] = field(default_factory=list)  # name, frame byte, size
    flags: list[tuple[str, int, int, str]] = field(default_factory=list)  # field, mask, value, name
    meanings: list[tuple[dict[str, int], str]] = field(default_factory=list)

    def decode(self, error_code: int, register: int, manufacturer: bytes) -> dict | None:
        """Named values of the manufacturer field (frame bytes 3..7), or None if none apply."""
        out: dict = {}
        for name, byte, size in self.fields:
            start = byte - 3
            if start < 0 or start + size > len(manufacturer):
                continue
            out[name] = int.from_bytes(manufacturer[start : start + size], "little")
        if not out:
            return None
        flag_names = [
            flag
            for fname, mask, value, flag in self.flags
            if fname in out and (out[fname] & mask) == value
        ]
        if any(fname in out for fname, *_ in self.flags):
            out["flags"] = flag_names
        known = {"error_code": error_code, "register": register, **out}
        for when, text in self.meanings:
            if all(known.get(k) == v for k, v in when.items()):
                out["meaning"] = text.format(**known)
                break
        return out


@dataclass
class Sidecar:
    key: str
    name: str
    notes: list[str] = field(default_factory=list)
    identity: dict[str, object] = field(default_factory=dict)
    signals: dict[tuple[int, int], SignalSpec] = field(default_factory=dict)
    unit_tables: dict[str, dict[int, UnitChoice]] = field(default_factory=dict)
    emcy: EmcySpec | None = None


def _int(value: object, where: str) -> int:
    if isinstance(value, int):
        return value
    if isinstance(value, str):
        try:
            return int(value, 0)
        except ValueError:
            pass
    raise ValueError(f"{where}: expected an integer, got {value!r}")


def _signals(raw: list[dict]) -> dict[tuple[int, int], SignalSpec]:
    out: dict[tuple[int, int], SignalSpec] = {}
    for i, item in enumerate(raw):
        where = f"signal #{i + 1}"
        index = _int(item["index"], where)
        subs = item.get("subindex", 0)
        subs = subs if isinstance(subs, list) else [subs]
        ctx_index = item.get("context_index")
        for sub in subs:
            sub = _int(sub, where)
            context = None
            if ctx_index is not None:
                context = (_int(ctx_index, where), _int(item.get("context_subindex", sub), where))
            out[(index, sub)] = SignalSpec(
                name=str(item["name"]).format(sub=sub, sub0=sub - 1),
                unit=item.get("unit"),
                scale=item.get("scale"),
                offset=float(item.get("offset", 0.0)),
                split=tuple(str(s).format(sub=sub, sub0=sub - 1) for s in item.get("split", ())),
                unit_table=item.get("unit_table"),
                context=context,
            )
    return out


def _emcy(raw: dict) -> EmcySpec:
    spec = EmcySpec()
    for f in raw.get("field", []):
        spec.fields.append(
            (f["name"], _int(f["byte"], "emcy field"), _int(f["size"], "emcy field"))
        )
    for f in raw.get("flag", []):
        mask = _int(f["mask"], "emcy flag")
        spec.flags.append((f["field"], mask, _int(f.get("value", mask), "emcy flag"), f["name"]))
    for m in raw.get("meaning", []):
        when = {k: _int(v, "emcy meaning") for k, v in m.get("when", {}).items()}
        spec.meanings.append((when, m["text"]))
    return spec


def load_sidecar(path: Path) -> Sidecar:
    """Read a sidecar TOML file; any problem is one InputError naming the file."""
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
        tables = {
            name: {
                _int(k, f"unit table {name}"): UnitChoice(
                    v.get("unit"), v.get("scale"), float(v.get("offset", 0.0)), v.get("label", "")
                )
                for k, v in table.items()
            }
            for name, table in raw.get("unit_tables", {}).items()
        }
        return Sidecar(
            key=raw.get("key", path.stem),  # a user's sidecar may leave them out
            name=raw.get("name", ""),
            notes=list(raw.get("notes", [])),
            identity=dict(raw.get("identity", {})),
            signals=_signals(raw.get("signal", [])),
            unit_tables=tables,
            emcy=_emcy(raw["emcy"]) if "emcy" in raw else None,
        )
    except (OSError, tomllib.TOMLDecodeError, KeyError, ValueError, TypeError) as exc:
        raise InputError(f"{path}: bad device sidecar: {exc}") from None
