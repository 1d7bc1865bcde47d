"""The network file (`--network FILE`, TOML or YAML): what is on the bus, as the user knows it.

Format and examples: docs/network-file.md. Every error names the file and the line
(YAML: from the composed node marks; TOML: tomllib's own position for syntax errors,
the key's line for the rest), because a wrong PDO mapping here silently gives wrong
values everywhere downstream.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from ..errors import InputError
from .pdo_map import COB_ID_INVALID
from .profile import BUILTIN_KEYS, load_builtin, load_eds
from .spec import NetworkSpec, NodeSpec

NODE_KEYS = {"device", "eds", "heartbeat_ms", "tpdo", "rpdo", "sdo_channels", "name"}
PDO_KEYS = {"cob_id", "enabled", "transmission_type", "inhibit_time", "event_timer", "mapping"}
_MAP_TEXT = re.compile(
    r"^\s*(?:0x)?([0-9a-fA-F]{1,4})\s*:\s*(?:0x)?([0-9a-fA-F]{1,2})\s*/\s*(\d{1,2})\s*$"
)


class _Lines:
    """Path (tuple of keys) -> 1-based line, to point at the offending entry."""

    def __init__(self, path: Path, text: str, yaml_node=None) -> None:
        self.path = path
        self.text = text.splitlines()
        self.map: dict[tuple, int] = {}
        if yaml_node is not None:
            self._walk(yaml_node, ())

    def _walk(self, node, where: tuple) -> None:
        import yaml

        self.map[where] = node.start_mark.line + 1
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                self.map[(*where, str(k.value))] = k.start_mark.line + 1
                self._walk(v, (*where, str(k.value)))
        elif isinstance(node, yaml.SequenceNode):
            for i, v in enumerate(node.value):
                self._walk(v, (*where, str(i)))

    def line(self, where: tuple) -> int | None:
        for n in range(len(where), -1, -1):
            if where[:n] in self.map:
                return self.map[where[:n]]
        # TOML: the key's own line inside a table header naming its parents, else its first use
        if not where:
            return None
        last, parents = re.escape(str(where[-1])), [str(k) for k in where[:-1]]
        header, first = "", None
        for i, text in enumerate(self.text, 1):
            h = re.match(r"^\s*\[+\s*([^\]]+?)\s*\]+", text)
            if h:
                header = h.group(1).replace('"', "")
                parts = header.split(".")
                if parts[-1] == str(where[-1]) and all(p in parts for p in parents):
                    return i
                continue
            if re.match(rf'^\s*"?{last}"?\s*=', text):
                if all(p in header.split(".") for p in parents[-1:]):
                    return i
                first = first or i
        return first

    def error(self, where: tuple, message: str) -> InputError:
        line = self.line(where)
        key = ".".join(str(k) for k in where)
        at = f"{self.path}:{line}" if line else str(self.path)
        return InputError(f"{at}: {key + ': ' if key else ''}{message}")


def _int(value, lines: _Lines, where: tuple, low: int = 0, high: int = 0xFFFFFFFF) -> int:
    if isinstance(value, str):
        try:
            value = int(value, 0)
        except ValueError:
            raise lines.error(where, f"expected an integer, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, int):
        raise lines.error(where, f"expected an integer, got {value!r}")
    if not low <= value <= high:
        raise lines.error(where, f"{value} is out of range {low}..{high}")
    return value


def _map_word(value, lines: _Lines, where: tuple) -> int:
    if isinstance(value, str):
        m = _MAP_TEXT.match(value)
        if m:
            index, sub, bits = int(m.group(1), 16), int(m.group(2), 16), int(m.group(3))
            if not 1 <= bits <= 64:
                raise lines.error(where, f"mapped length {bits} bits is not 1..64")
            return index << 16 | sub << 8 | bits
        if not value.strip().lower().startswith("0x"):
            raise lines.error(
                where, f"mapping entry {value!r} is neither 0xIIIISSLL nor 'IIII:SS/bits'"
            )
    word = _int(value, lines, where)
    if not 1 <= word & 0xFF <= 64:
        raise lines.error(
            where, f"mapping word 0x{word:08X}: length {word & 0xFF} bits is not 1..64"
        )
    return word


def _pdo(
    raw, direction: str, number: int, node: int, lines: _Lines, where: tuple
) -> list[tuple[int, int, int]]:
    if not isinstance(raw, dict):
        raise lines.error(where, "expected a table of PDO parameters")
    unknown = set(raw) - PDO_KEYS
    if unknown:
        raise lines.error(
            (*where, sorted(unknown)[0]),
            f"unknown PDO parameter (known: {', '.join(sorted(PDO_KEYS))})",
        )
    comm = (0x1800 if direction == "tpdo" else 0x1400) + number - 1
    mapping = (0x1A00 if direction == "tpdo" else 0x1600) + number - 1
    writes: list[tuple[int, int, int]] = []
    if "cob_id" in raw or "enabled" in raw:
        if "cob_id" in raw:
            cob = _int(raw["cob_id"], lines, (*where, "cob_id"), 1, 0x7FF)
        elif 1 <= number <= 4:
            cob = (0x180 if direction == "tpdo" else 0x200) + 0x100 * (number - 1) + node
        else:
            raise lines.error(
                where, f"{direction}{number} needs a cob_id (no predefined one above PDO 4)"
            )
        enabled = raw.get("enabled", True)
        if not isinstance(enabled, bool):
            raise lines.error((*where, "enabled"), f"expected true or false, got {enabled!r}")
        writes.append((comm, 1, cob | (0 if enabled else COB_ID_INVALID)))
    for key, sub, high in (
        ("transmission_type", 2, 255),
        ("inhibit_time", 3, 0xFFFF),
        ("event_timer", 5, 0xFFFF),
    ):
        if key in raw:
            writes.append((comm, sub, _int(raw[key], lines, (*where, key), 0, high)))
    if "mapping" in raw:
        entries = raw["mapping"]
        if not isinstance(entries, list):
            raise lines.error((*where, "mapping"), "expected a list of mapping entries")
        words = [_map_word(v, lines, (*where, "mapping", str(i))) for i, v in enumerate(entries)]
        if sum(w & 0xFF for w in words) > 64:
            raise lines.error(
                (*where, "mapping"), f"maps {sum(w & 0xFF for w in words)} bits; a PDO holds 64"
            )
        writes.append((mapping, 0, 0))
        writes += [(mapping, i + 1, w) for i, w in enumerate(words)]
        writes.append((mapping, 0, len(words)))
    return writes


def _node(raw, node: int, base: Path, lines: _Lines, where: tuple) -> NodeSpec:
    if not isinstance(raw, dict):
        raise lines.error(where, "expected a table of node settings")
    unknown = set(raw) - NODE_KEYS
    if unknown:
        raise lines.error(
            (*where, sorted(unknown)[0]),
            f"unknown node setting (known: {', '.join(sorted(NODE_KEYS))})",
        )
    spec = NodeSpec(how="network file")
    if "device" in raw and "eds" in raw:
        raise lines.error(where, "give either device or eds, not both")
    if "device" in raw:
        key = str(raw["device"]).lower().replace("-", "").replace(" ", "")
        if key not in BUILTIN_KEYS:
            raise lines.error(
                (*where, "device"),
                f"unknown device {raw['device']!r} (known: {', '.join(BUILTIN_KEYS)})",
            )
        spec.profile = load_builtin(key)
    if "eds" in raw:
        path = Path(str(raw["eds"]))
        path = path if path.is_absolute() else base / path
        if not path.exists():
            raise lines.error((*where, "eds"), f"no such EDS/DCF file: {path}")
        try:
            spec.profile = load_eds(path, node)
        except InputError as exc:
            raise lines.error((*where, "eds"), str(exc)) from None
    if "heartbeat_ms" in raw:
        spec.writes.append(
            (0x1017, 0, _int(raw["heartbeat_ms"], lines, (*where, "heartbeat_ms"), 0, 0xFFFF))
        )
    for direction in ("tpdo", "rpdo"):
        table = raw.get(direction, {})
        if not isinstance(table, dict):
            raise lines.error((*where, direction), "expected a table keyed by PDO number")
        for num, params in table.items():
            number = _int(num, lines, (*where, direction, str(num)), 1, 512)
            spec.writes += _pdo(
                params, direction, number, node, lines, (*where, direction, str(num))
            )
    channels = raw.get("sdo_channels", [])
    if not isinstance(channels, list):
        raise lines.error((*where, "sdo_channels"), "expected a list of {request, response} tables")
    for i, ch in enumerate(channels):
        w = (*where, "sdo_channels", str(i))
        if not isinstance(ch, dict) or set(ch) != {"request", "response"}:
            raise lines.error(w, "an SDO channel is {request = COB-ID, response = COB-ID}")
        spec.sdo_channels.append(
            (
                _int(ch["request"], lines, (*w, "request"), 1, 0x7FF),
                _int(ch["response"], lines, (*w, "response"), 1, 0x7FF),
            )
        )
    return spec


def load_network(path: str | Path) -> NetworkSpec:
    """Read and check a network file; EDS paths are relative to the file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot read network file: {exc.strerror or exc}") from None
    if path.suffix.lower() == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"{path}: {exc}") from None
        lines = _Lines(path, text)
    else:
        import yaml

        try:
            composed = yaml.compose(text, Loader=yaml.SafeLoader)
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            at = f"{path}:{mark.line + 1}" if mark else str(path)
            raise InputError(f"{at}: {getattr(exc, 'problem', None) or exc}") from None
        lines = _Lines(path, text, composed)
    if not isinstance(data, dict):
        raise InputError(
            f"{path}: a network file is a table with 'nodes' (and optionally 'bitrate')"
        )
    unknown = set(data) - {"nodes", "bitrate"}
    if unknown:
        raise lines.error((sorted(unknown)[0],), "unknown top-level key (known: bitrate, nodes)")
    spec = NetworkSpec(source=str(path))
    if "bitrate" in data:
        spec.bitrate = _int(data["bitrate"], lines, ("bitrate",), 1, 8_000_000)
    nodes = data.get("nodes", {})
    if not isinstance(nodes, dict):
        raise lines.error(("nodes",), "expected a table keyed by node-ID")
    for key, raw in nodes.items():
        node = _int(key, lines, ("nodes", str(key)), 1, 127)
        spec.nodes[node] = _node(raw, node, path.parent, lines, ("nodes", str(key)))
    return spec
