"""The network file (`--network FILE`, TOML or YAML) and the rules file's `network:` section.

One schema for both (docs/network-file.md), read in two steps: `read_network`
checks one source's tree and gives its settings as a normalised table (node-IDs and
PDO numbers as integers, the device or EDS as one loaded profile); `combine` lays
sources over each other, the later winning key by key, and turns the result into the
object values of a NetworkSpec. Every error names the file and the line, because a
wrong PDO mapping here silently gives wrong values everywhere downstream.
"""

from __future__ import annotations

import re
from pathlib import Path

from cananalyze.config.filelines import Lines, integer, read_tree
from cananalyze.config.legacy_keys import translate
from cananalyze.config.spec import NetworkSpec, NodeSpec
from cananalyze.core.errors import InputError
from cananalyze.core.text import printable
from cananalyze.devices.builtin import load_builtin
from cananalyze.devices.catalog import device_keys
from cananalyze.devices.profile import load_eds
from cananalyze.protocol import mpdo as mpdo_layout
from cananalyze.protocol import srdo as srdo_layout
from cananalyze.protocol.datatypes import DATA_TYPES
from cananalyze.protocol.pdo_map import COB_ID_INVALID

TOP_KEYS = {"bitrate", "canopen_fd", "nodes", "sync", "known_cob_ids"}
NODE_KEYS = {
    "device",
    "eds",
    "name",
    "heartbeat_ms",
    "heartbeat_consumer",
    "guard_time_ms",
    "life_time_factor",
    "emcy_inhibit_time",
    "tpdo",
    "rpdo",
    "sdo_channels",
    "signals",
    "srdo",
    *("object_scanner_list", "object_dispatching_list"),
    "gfc",
    "canopen_fd",
}
# node setting -> the MPDO object list it fills (protocol/mpdo.py LISTS): the node's first
# list of that kind (0x1FA0 / 0x1FD0), sub 1.. the entries, sub 0 their number
MPDO_LISTS = {
    "object_scanner_list": mpdo_layout.SCANNER,
    "object_dispatching_list": mpdo_layout.DISPATCHER,
}
# a PDO's `mpdo`: its mapping's number of entries (0xFE SAM, 0xFF DAM)
MPDO_MODES = {name: count for count, name in mpdo_layout.MODES.items()}
# [nodes.N.srdo.K] (CiA 304, protocol/srdo.py): key -> (communication sub-index, highest value)
SRDO_OBJECTS = {
    "sct_ms": (srdo_layout.SUB_SCT, 0xFFFF),
    "srvt_ms": (srdo_layout.SUB_SRVT, 0xFF),
}
SRDO_KEYS = {"direction", "cob_id", "mapping", *SRDO_OBJECTS}
SRDO_DIRECTIONS = {"tx": 1, "rx": 2}
SIGNAL_KEYS = {"name", "unit", "scale", "offset"}
PDO_KEYS = {
    "cob_id",
    "enabled",
    "transmission_type",
    "inhibit_time",
    "event_timer",
    "mapping",
    "length",
    "mpdo",
}
# node setting -> (object, highest value): each becomes a write of that object's sub 0
NODE_OBJECTS = {
    "heartbeat_ms": (0x1017, 0xFFFF),
    "guard_time_ms": (0x100C, 0xFFFF),
    "life_time_factor": (0x100D, 0xFF),
    "emcy_inhibit_time": (0x1015, 0xFFFF),
}
PDO_OBJECTS = {
    "transmission_type": (2, 0xFF),
    "inhibit_time": (3, 0xFFFF),
    "event_timer": (5, 0xFFFF),
}
SYNC_OBJECTS = {"period_us": 0x1006, "window_us": 0x1007}
_OBJECT_TEXT = re.compile(r"^\s*(?:0x)?([0-9a-fA-F]{1,4})\s*:\s*(?:0x)?([0-9a-fA-F]{1,2})\s*$")
_MAP_TEXT = re.compile(
    r"^\s*(?:0x)?([0-9a-fA-F]{1,4})\s*:\s*(?:0x)?([0-9a-fA-F]{1,2})\s*/\s*(\d{1,2})\s*$"
)


def _table(value, lines: Lines, where: tuple, what: str) -> dict:
    if not isinstance(value, dict):
        shown = "a list" if isinstance(value, list) else repr(value)
        raise lines.error(where, f"expected a table {what}, got {shown}")
    return value


def _known(raw: dict, keys: set[str], lines: Lines, where: tuple, what: str) -> None:
    unknown = sorted(set(map(str, raw)) - keys)
    if unknown:
        raise lines.error(
            (*where, unknown[0]), f"unknown {what} (known: {', '.join(sorted(keys))})"
        )


def _map_word(value, lines: Lines, where: tuple) -> int:
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
    word = integer(value, lines, where)
    if not 1 <= word & 0xFF <= 64:
        raise lines.error(
            where, f"mapping word 0x{word:08X}: length {word & 0xFF} bits is not 1..64"
        )
    return word


def _pdo(raw, lines: Lines, where: tuple, fd: bool = False) -> dict:
    """One PDO's parameters; `fd`: of a CANopen FD node (CiA 1301), up to 64 bytes."""
    most = 512 if fd else 64
    raw = _table(raw, lines, where, "of PDO parameters")
    _known(raw, PDO_KEYS, lines, where, "PDO parameter")
    out: dict = {"_at": (lines, where)}  # for the one check left to combine(): a cob_id
    if "cob_id" in raw:
        out["cob_id"] = integer(raw["cob_id"], lines, (*where, "cob_id"), 1, 0x7FF)
    if "enabled" in raw:
        if not isinstance(raw["enabled"], bool):
            raise lines.error(
                (*where, "enabled"), f"expected true or false, got {raw['enabled']!r}"
            )
        out["enabled"] = raw["enabled"]
    for key, (_, high) in PDO_OBJECTS.items():
        if key in raw:
            out[key] = integer(raw[key], lines, (*where, key), 0, high)
    if "length" in raw:
        out["length"] = integer(raw["length"], lines, (*where, "length"), 0, most // 8)
    if "mpdo" in raw:
        if raw["mpdo"] not in MPDO_MODES:
            raise lines.error((*where, "mpdo"), f'expected "sam" or "dam", got {raw["mpdo"]!r}')
        out["mpdo"] = raw["mpdo"]
    if "mapping" in raw:
        entries = raw["mapping"]
        if not isinstance(entries, list):
            raise lines.error((*where, "mapping"), "expected a list of mapping entries")
        words = [_map_word(v, lines, (*where, "mapping", str(i))) for i, v in enumerate(entries)]
        if sum(w & 0xFF for w in words) > most:
            holds = "512 (CANopen FD)" if fd else "64 (512 on a CANopen FD node: canopen_fd)"
            raise lines.error(
                (*where, "mapping"),
                f"maps {sum(w & 0xFF for w in words)} bits; a PDO holds {holds}",
            )
        out["mapping"] = words
    return out


def _srdo(raw, lines: Lines, where: tuple, number: int, node: int) -> dict:
    """One SRDO's parameters: direction, SCT, SRVT, the normal COB-ID (the inverted one is
    the next: CANopenNode's CO_SRDO_config requires it) and the mapping, whose entries
    alternate between the normal and the inverted frame's objects."""
    raw = _table(raw, lines, where, "of SRDO parameters")
    _known(raw, SRDO_KEYS, lines, where, "SRDO parameter")
    direction = raw.get("direction", "tx")
    if direction not in SRDO_DIRECTIONS:
        raise lines.error((*where, "direction"), f"expected tx or rx, got {direction!r}")
    out: dict = {"direction": SRDO_DIRECTIONS[direction]}
    for key, (_, high) in SRDO_OBJECTS.items():
        if key in raw:
            out[key] = integer(raw[key], lines, (*where, key), 0, high)
    default = srdo_layout.default_cob_ids(node) if number == 1 else None
    if "cob_id" in raw:
        cob = integer(raw["cob_id"], lines, (*where, "cob_id"), 1, 0x7FF)
        if not (srdo_layout.FIRST_COB <= cob < srdo_layout.LAST_COB and cob % 2):
            raise lines.error(
                (*where, "cob_id"), f"0x{cob:03X}: an SRDO's normal COB-ID is odd, 0x101-0x17F"
            )
        out["cob_id"] = cob
    elif default is not None:
        out["cob_id"] = default[0]
    else:
        raise lines.error(where, f"srdo {number} needs a cob_id (only SRDO 1 has a default)")
    if "mapping" in raw:
        entries = raw["mapping"]
        if not isinstance(entries, list) or len(entries) % 2 or len(entries) > 16:
            raise lines.error(
                (*where, "mapping"),
                "expected a list of an even number of entries (at most 16), normal then inverted",
            )
        out["mapping"] = [
            _map_word(v, lines, (*where, "mapping", str(i))) for i, v in enumerate(entries)
        ]
    return out


def _number(value, lines: Lines, where: tuple) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise lines.error(where, f"expected a number, got {value!r}")
    return float(value)


def _signals(raw, lines: Lines, where: tuple) -> dict:
    """`signals = {"6401:01" = {name, unit, scale, offset}}`: how to show a mapped object,
    over the profile's (and its sidecar's) name, unit and scaling."""
    table = _table(raw, lines, where, 'keyed by object ("INDEX:SUB")')
    out: dict = {}
    for key, spec in table.items():
        at = (*where, str(key))
        m = _OBJECT_TEXT.match(str(key))
        if not m:
            raise lines.error(at, f"signal key {key!r} is not an object 'INDEX:SUB' (hex)")
        spec = _table(spec, lines, at, "with name, unit, scale, offset")
        _known(spec, SIGNAL_KEYS, lines, at, "signal setting")
        one: dict = {}
        for k in ("name", "unit"):
            if k in spec:
                if not isinstance(spec[k], str) or (k == "name" and not spec[k].strip()):
                    raise lines.error((*at, k), f"expected text, got {spec[k]!r}")
                one[k] = printable(spec[k])  # the file's text, as a terminal may show it
        for k in ("scale", "offset"):
            if k in spec:
                one[k] = _number(spec[k], lines, (*at, k))
        out[f"{int(m.group(1), 16):04X}:{int(m.group(2), 16):02X}"] = one
    return out


def _profile(raw: dict, node: int, base: Path, lines: Lines, where: tuple, how: str):
    if "device" in raw and "eds" in raw:
        raise lines.error(where, "give either device or eds, not both")
    if "device" in raw:
        key = str(raw["device"]).lower().replace("-", "").replace(" ", "")
        if key not in device_keys():
            raise lines.error(
                (*where, "device"),
                f"unknown device {raw['device']!r} (known: {', '.join(device_keys())})",
            )
        return load_builtin(key), how
    path = Path(str(raw["eds"]))
    path = path if path.is_absolute() else base / path
    if not path.exists():
        raise lines.error((*where, "eds"), f"no such EDS/DCF file: {path}")
    try:
        return load_eds(path, node), how
    except InputError as exc:
        raise lines.error((*where, "eds"), str(exc)) from None


def _node(
    raw, node: int, base: Path, lines: Lines, where: tuple, how: str, network_fd: bool = False
) -> dict:
    raw = _table(raw, lines, where, "of node settings")
    _known(raw, NODE_KEYS, lines, where, "node setting")
    out: dict = {}
    if "device" in raw or "eds" in raw:
        out["profile"] = _profile(raw, node, base, lines, where, how)
    if "name" in raw:
        out["name"] = printable(str(raw["name"]))
    if "gfc" in raw:  # CiA 304 GFC parameter (0x1300): true = 1, the node may send GFC
        if not isinstance(raw["gfc"], bool):
            raise lines.error((*where, "gfc"), f"expected true or false, got {raw['gfc']!r}")
        out["gfc"] = raw["gfc"]
    if "canopen_fd" in raw:  # CiA 1301: its SDO COB-IDs carry USDO frames
        out["canopen_fd"] = _flag(raw["canopen_fd"], lines, (*where, "canopen_fd"))
    for key, (_, high) in NODE_OBJECTS.items():
        if key in raw:
            out[key] = integer(raw[key], lines, (*where, key), 0, high)
    if "heartbeat_consumer" in raw:
        w = (*where, "heartbeat_consumer")
        table = _table(raw["heartbeat_consumer"], lines, w, "of producer node-ID = consumer ms")
        out["heartbeat_consumer"] = _keyed(
            table,
            lines,
            w,
            1,
            127,
            lambda v, at, _: integer(v, lines, at, 0, 0xFFFF),
        )
    for direction in ("tpdo", "rpdo"):
        if direction in raw:
            w = (*where, direction)
            table = _table(raw[direction], lines, w, "keyed by PDO number")
            fd = bool(out.get("canopen_fd") or network_fd)  # CiA 1301: 64-byte PDOs
            out[direction] = _keyed(
                table, lines, w, 1, 512, lambda v, at, _, fd=fd: _pdo(v, lines, at, fd)
            )
    if "srdo" in raw:
        w = (*where, "srdo")
        table = _table(raw["srdo"], lines, w, "keyed by SRDO number")
        out["srdo"] = _keyed(
            table, lines, w, 1, srdo_layout.COUNT, lambda v, at, k: _srdo(v, lines, at, k, node)
        )
    for key, kind in MPDO_LISTS.items():
        if key in raw:
            w = (*where, key)
            if not isinstance(raw[key], list) or len(raw[key]) > 254:
                raise lines.error(w, "expected a list of at most 254 entries (integers)")
            high = (1 << DATA_TYPES[mpdo_layout.LISTS[kind].data_type].bits) - 1
            out[key] = [integer(v, lines, (*w, str(i)), 0, high) for i, v in enumerate(raw[key])]
    if "signals" in raw:
        out["signals"] = _signals(raw["signals"], lines, (*where, "signals"))
    if "sdo_channels" in raw:
        channels = raw["sdo_channels"]
        w = (*where, "sdo_channels")
        if not isinstance(channels, list):
            raise lines.error(w, "expected a list of {request, response} tables")
        out["sdo_channels"] = []
        for i, ch in enumerate(channels):
            at = (*w, str(i))
            if not isinstance(ch, dict) or set(ch) != {"request", "response"}:
                raise lines.error(at, "an SDO channel is {request = COB-ID, response = COB-ID}")
            out["sdo_channels"].append(
                (
                    integer(ch["request"], lines, (*at, "request"), 1, 0x7FF),
                    integer(ch["response"], lines, (*at, "response"), 1, 0x7FF),
                )
            )
    return out


def _keyed(table: dict, lines: Lines, where: tuple, low: int, high: int, read) -> dict:
    """A table keyed by integers (node-IDs, PDO numbers): keys checked, values read."""
    out: dict = {}
    for key, value in table.items():
        at = (*where, str(key))
        number = integer(key, lines, at, low, high)
        if number in out:
            raise lines.error(at, f"{number} is given twice")
        out[number] = read(value, at, number)
    return out


def _flag(value, lines: Lines, where: tuple) -> bool:
    if not isinstance(value, bool):
        raise lines.error(where, f"expected true or false, got {value!r}")
    return value


def read_network(data, lines: Lines, base: Path, how: str = "network file") -> dict:
    """Check one source's network tree; its settings as a normalised table (see combine).

    Deprecated keys are translated first (one warning each on stderr)."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise lines.error((), "a network description is a table with 'nodes' (and 'bitrate', "
                          "'sync', 'known_cob_ids')")  # fmt: skip
    data = translate(data, lines, base)
    _known(data, TOP_KEYS, lines, (), "top-level key")
    out: dict = {}
    if "bitrate" in data:
        out["bitrate"] = integer(data["bitrate"], lines, ("bitrate",), 1, 8_000_000)
    if "canopen_fd" in data:  # CiA 1301: every node's SDO COB-IDs carry USDO frames
        out["canopen_fd"] = _flag(data["canopen_fd"], lines, ("canopen_fd",))
    if "sync" in data:
        sync = _table(data["sync"], lines, ("sync",), "with period_us and window_us")
        _known(sync, set(SYNC_OBJECTS), lines, ("sync",), "sync setting")
        out["sync"] = {k: integer(v, lines, ("sync", k)) for k, v in sync.items()}
    if "known_cob_ids" in data:
        ids = data["known_cob_ids"]
        if not isinstance(ids, list):
            raise lines.error(("known_cob_ids",), "expected a list of identifiers")
        out["known_cob_ids"] = [
            integer(v, lines, ("known_cob_ids", str(i)), 0, 0x1FFFFFFF) for i, v in enumerate(ids)
        ]
    if "nodes" in data:
        nodes = _table(data["nodes"], lines, ("nodes",), "keyed by node-ID")
        out["nodes"] = _keyed(
            nodes,
            lines,
            ("nodes",),
            1,
            127,
            lambda v, at, node: _node(v, node, base, lines, at, how, bool(out.get("canopen_fd"))),
        )
    return out


def _merge(low: dict, high: dict) -> dict:
    """`high` over `low`, key by key: tables merge, everything else is replaced. A node's
    device or EDS is one setting (the `profile` entry)."""
    out = dict(low)
    for key, value in high.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def combine(*settings: dict, source: str | None = None) -> NetworkSpec:
    """The NetworkSpec of sources laid over each other in order (the last wins per key)."""
    tree: dict = {}
    for s in settings:
        tree = _merge(tree, s)
    spec = NetworkSpec(source=source, bitrate=tree.get("bitrate"))
    spec.canopen_fd = bool(tree.get("canopen_fd", False))
    spec.known_cob_ids = set(tree.get("known_cob_ids", ()))
    spec.bus_writes = [(SYNC_OBJECTS[k], 0, v) for k, v in sorted(tree.get("sync", {}).items())]
    for node, raw in sorted(tree.get("nodes", {}).items()):
        spec.nodes[node] = _node_spec(node, raw)
    return spec


def _node_spec(node: int, raw: dict) -> NodeSpec:
    profile, how = raw.get("profile", (None, "network file"))
    spec = NodeSpec(profile=profile, how=how if profile is not None else "unknown")
    spec.name = raw.get("name")
    spec.canopen_fd = bool(raw.get("canopen_fd", False))
    for key, (index, _) in NODE_OBJECTS.items():
        if key in raw:
            spec.writes.append((index, 0, raw[key]))
    if "gfc" in raw:
        spec.writes.append((srdo_layout.GFC_PARAMETER, 0, int(raw["gfc"])))
    consumers = sorted(raw.get("heartbeat_consumer", {}).items())
    spec.writes += [(0x1016, i + 1, p << 16 | ms) for i, (p, ms) in enumerate(consumers)]
    for direction in ("tpdo", "rpdo"):
        for number, params in sorted(raw.get(direction, {}).items()):
            spec.writes += _pdo_writes(params, direction, number, node, profile)
            if "length" in params:
                spec.pdo_lengths[("tx" if direction == "tpdo" else "rx", number)] = params["length"]
    for number, params in sorted(raw.get("srdo", {}).items()):
        comm = srdo_layout.COMM_BASE + number - 1
        mapping = srdo_layout.MAP_BASE + number - 1
        spec.writes.append((comm, srdo_layout.SUB_DIRECTION, params["direction"]))
        for key, (sub, _) in SRDO_OBJECTS.items():
            if key in params:
                spec.writes.append((comm, sub, params[key]))
        spec.writes.append((comm, srdo_layout.SUB_NORMAL, params["cob_id"]))
        spec.writes.append((comm, srdo_layout.SUB_INVERTED, params["cob_id"] + 1))
        if "mapping" in params:
            words = params["mapping"]
            spec.writes += [(mapping, i + 1, w) for i, w in enumerate(words)]
            spec.writes.append((mapping, 0, len(words)))
    for key, kind in MPDO_LISTS.items():
        if key in raw:
            first = mpdo_layout.LISTS[kind].first
            spec.writes += [(first, i + 1, e) for i, e in enumerate(raw[key])]
            spec.writes.append((first, 0, len(raw[key])))
    spec.sdo_channels = list(raw.get("sdo_channels", ()))
    for key, one in raw.get("signals", {}).items():
        index, sub = (int(x, 16) for x in key.split(":"))
        spec.signals[(index, sub)] = one
    return spec


def _pdo_writes(params: dict, direction: str, number: int, node: int, profile):
    comm = (0x1800 if direction == "tpdo" else 0x1400) + number - 1
    mapping = (0x1A00 if direction == "tpdo" else 0x1600) + number - 1
    writes: list[tuple[int, int, int]] = []
    if "cob_id" in params or "enabled" in params:
        cob = params.get("cob_id")
        if cob is None:  # only `enabled`: the COB-ID in force (profile, else predefined)
            known = profile.value(comm, 1, node) if profile is not None else None
            if isinstance(known, int) and known & 0x7FF:
                cob = known & 0x7FF
            elif 1 <= number <= 4:
                cob = (0x180 if direction == "tpdo" else 0x200) + 0x100 * (number - 1) + node
            else:
                lines, where = params["_at"]
                raise lines.error(
                    where, f"{direction}{number} needs a cob_id (no predefined one above PDO 4)"
                )
        writes.append((comm, 1, cob | (0 if params.get("enabled", True) else COB_ID_INVALID)))
    for key, (sub, _) in PDO_OBJECTS.items():
        if key in params:
            writes.append((comm, sub, params[key]))
    if "mapping" in params:
        words = params["mapping"]
        writes.append((mapping, 0, 0))
        writes += [(mapping, i + 1, w) for i, w in enumerate(words)]
        writes.append((mapping, 0, len(words)))
    if "mpdo" in params:  # after the entries: the count says the PDO is an MPDO
        writes.append((mapping, 0, MPDO_MODES[params["mpdo"]]))
    return writes


def read_network_file(path: str | Path) -> dict:
    """One network file's checked settings (for combine); EDS paths relative to the file."""
    data, lines = read_tree(path, "network file")
    return read_network(data, lines, Path(path).parent)


def load_network(path: str | Path) -> NetworkSpec:
    """Read and check a network file; EDS paths are relative to the file."""
    return combine(read_network_file(path), source=str(path))
