"""Deprecated spellings of the network schema, translated to today's keys.

The rules file's `network:` section had its own names for the network file's
settings (`profile`, `inhibit_100us`, `event_timer_ms`, `emcy_inhibit_100us`, and a
global `pdos:` table keyed by COB-ID). They keep working: each is rewritten to the
current key, with one warning per key and file naming the line, and errors in their
values still point at the line the user wrote.
"""

from __future__ import annotations

from pathlib import Path

from cananalyze.config.filelines import Lines, integer
from cananalyze.core.errors import InputError
from cananalyze.devices.builtin import load_builtin
from cananalyze.devices.catalog import device_keys
from cananalyze.devices.profile import load_eds

NODE_RENAMES = {"emcy_inhibit_100us": "emcy_inhibit_time"}
PDO_RENAMES = {"inhibit_100us": "inhibit_time", "event_timer_ms": "event_timer"}
_DIRECTIONS = {"tx": "tpdo", "rx": "rpdo", "tpdo": "tpdo", "rpdo": "rpdo"}


def translate(data: dict, lines: Lines, base: Path) -> dict:
    """The same tree in today's keys (a copy: the caller's dicts are not changed)."""
    data = dict(data)
    if "pdos" in data:
        _pdos(data, lines, base)
    nodes = data.get("nodes")
    if isinstance(nodes, dict):
        data["nodes"] = {k: _node(v, lines, ("nodes", str(k))) for k, v in nodes.items()}
    return data


def _rename(table: dict, old: str, new: str, lines: Lines, where: tuple) -> None:
    if old not in table:
        return
    if new in table:
        raise lines.error((*where, old), f"give {new} or the deprecated {old}, not both")
    lines.deprecated((*where, old), old, f"'{new}'")
    table[new] = table.pop(old)
    lines.alias((*where, new), (*where, old))


def _node(raw, lines: Lines, where: tuple):
    if not isinstance(raw, dict):
        return raw  # read_network says what is wrong
    raw = dict(raw)
    if "profile" in raw:
        if "device" in raw or "eds" in raw:
            raise lines.error((*where, "profile"), "give device or eds, not profile as well")
        value = raw.pop("profile")
        key = str(value).lower().replace("-", "").replace(" ", "")
        new = "device" if key in device_keys() else "eds"
        lines.deprecated((*where, "profile"), "profile", "'device' (built-in) or 'eds' (file)")
        raw[new] = value
        lines.alias((*where, new), (*where, "profile"))
    for old, new in NODE_RENAMES.items():
        _rename(raw, old, new, lines, where)
    for direction in ("tpdo", "rpdo"):
        table = raw.get(direction)
        if isinstance(table, dict):
            raw[direction] = {
                n: _pdo(p, lines, (*where, direction, str(n))) for n, p in table.items()
            }
    return raw


def _pdo(raw, lines: Lines, where: tuple):
    if not isinstance(raw, dict):
        return raw
    raw = dict(raw)
    for old, new in PDO_RENAMES.items():
        _rename(raw, old, new, lines, where)
    return raw


def _pdos(data: dict, lines: Lines, base: Path) -> None:
    """`pdos: {COB-ID: {node, direction, number, ...}}` -> nodes.<node>.<tpdo|rpdo>.<number>."""
    pdos = data.pop("pdos")
    if not isinstance(pdos, dict):
        raise lines.error(("pdos",), "expected a table keyed by COB-ID")
    lines.deprecated(("pdos",), "pdos", "the node's tpdo/rpdo tables (nodes.N.tpdo.M)")
    nodes = data.get("nodes", {})
    if not isinstance(nodes, dict):
        raise lines.error(("nodes",), "expected a table keyed by node-ID")
    nodes = data["nodes"] = dict(nodes)
    for cob_key, entry in pdos.items():
        at = ("pdos", f"0x{cob_key:03X}" if isinstance(cob_key, int) else str(cob_key))
        lines.alias(at, ("pdos", str(cob_key)))  # messages show a COB-ID in hex
        cob = integer(cob_key, lines, at, 1, 0x7FF)
        if not isinstance(entry, dict) or "node" not in entry:
            raise lines.error(at, "each PDO here needs at least node:")
        node = integer(entry["node"], lines, (*at, "node"), 1, 127)
        key = next((k for k in nodes if _as_int(k) == node), node)
        table = nodes.get(key) or {}
        if not isinstance(table, dict):
            raise lines.error(("nodes", str(key)), "expected a table of node settings")
        direction, number = _which(entry, cob, node, table, lines, at, base)
        pdo_table = dict(table.get(direction) or {})
        if any(_as_int(n) == number for n in pdo_table):
            raise lines.error(at, f"{direction} {number} of node {node} is also in nodes:")
        params = {k: v for k, v in entry.items() if k not in ("node", "direction", "number")}
        pdo_table[number] = {"cob_id": cob, **params}
        nodes[key] = {**table, direction: pdo_table}
        lines.alias(("nodes", str(key), direction, str(number)), at)
        lines.alias(("nodes", str(key), direction, str(number), "cob_id"), at)


def _which(entry: dict, cob: int, node: int, table: dict, lines, at, base) -> tuple[str, int]:
    """(tpdo|rpdo, number) of an old `pdos` entry: as given, else the predefined set or the
    node's profile that has this COB-ID."""
    direction = entry.get("direction")
    if direction is not None:
        if direction not in _DIRECTIONS:
            raise lines.error((*at, "direction"), f"direction is tx or rx, not {direction!r}")
        direction = _DIRECTIONS[direction]
    number = entry.get("number")
    if number is not None:
        number = integer(number, lines, (*at, "number"), 1, 512)
        return direction or "tpdo", number
    found = [
        (d, n)
        for d, first in (("tpdo", 0x180), ("rpdo", 0x200))
        for n in range(1, 5)
        if first + 0x100 * (n - 1) + node == cob and direction in (None, d)
    ]
    if not found:
        profile = _profile_of(table, node, base)
        for p in profile.pdos(node) if profile is not None else ():
            d = "tpdo" if p.direction == "tx" else "rpdo"
            if p.cob_id == cob and direction in (None, d):
                found.append((d, p.number))
    if len(found) != 1:
        raise lines.error(
            at, f"give number: (and direction:): 0x{cob:03X} is not one PDO of node {node}"
        )
    return found[0]


def _profile_of(table: dict, node: int, base: Path):
    name = table.get("device") or table.get("profile") or table.get("eds")
    if name is None:
        return None
    key = str(name).lower().replace("-", "").replace(" ", "")
    try:
        if key in device_keys():
            return load_builtin(key)
        path = Path(str(name))
        return load_eds(path if path.is_absolute() else base / path, node)
    except (InputError, OSError):
        return None  # read_network reports the bad profile itself


def _as_int(key) -> int | None:
    try:
        return int(str(key), 0)
    except ValueError:
        return None
