"""Which nodes the simulator emulates: a network file, or the four seed devices.

Format (TOML), until the project's own network file documents more:

    bitrate = 500000
    [nodes.3]
    device = "mcb560"          # a built-in profile
    [nodes.12]
    eds = "my_device.eds"      # or any EDS/DCF, relative to this file
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from ..errors import InputError
from ..network.profile import DeviceProfile, load_builtin, load_eds

# The default bus: one of each seed device (node IDs as in samples/network.toml).
DEFAULT_NODES = {3: "mcb560", 5: "dat7014", 6: "dat7130", 7: "i7231d"}


def default_network() -> dict[int, DeviceProfile]:
    return {node: load_builtin(key) for node, key in DEFAULT_NODES.items()}


def load_network(path: str | Path) -> tuple[dict[int, DeviceProfile], int]:
    """(node id -> profile, bitrate) from a network file; InputError naming the problem."""
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except OSError as exc:
        raise InputError(f"{path}: cannot read network file: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    nodes: dict[int, DeviceProfile] = {}
    for key, spec in raw.get("nodes", {}).items():
        where = f"{path}: [nodes.{key}]"
        try:
            node = int(key, 0)
        except ValueError:
            raise InputError(f"{where}: node id must be a number 1-127") from None
        if not 1 <= node <= 127:
            raise InputError(f"{where}: node id must be 1-127")
        if not isinstance(spec, dict) or ("device" in spec) == ("eds" in spec):
            raise InputError(f'{where}: give exactly one of device = "key" or eds = "file"')
        try:
            if "device" in spec:
                nodes[node] = load_builtin(str(spec["device"]))
            else:
                nodes[node] = load_eds(path.parent / str(spec["eds"]), node)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
    if not nodes:
        raise InputError(f"{path}: no [nodes.N] tables")
    bitrate = raw.get("bitrate", 500_000)
    if not isinstance(bitrate, int) or bitrate <= 0:
        raise InputError(f"{path}: bitrate must be a positive integer")
    return nodes, bitrate
