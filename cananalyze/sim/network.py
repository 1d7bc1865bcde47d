"""Which nodes the simulator emulates: the project's network file, or the four seed devices.

The network file is the analyser's own (docs/network-file.md, read by
`cananalyze.config.netfile`), so one file describes the bus to both. Its node
settings (heartbeat, consumer heartbeat, guarding, EMCY inhibit, PDO settings) become
the node's stored parameters: applied over the profile defaults at every reset, as a
configured device keeps them. The bus-wide [sync] and known_cob_ids are the analyser's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from cananalyze.core.errors import InputError
from cananalyze.devices.builtin import load_builtin
from cananalyze.devices.profile import DeviceProfile

# The default bus: one of each seed device (node IDs as in samples/network.toml).
DEFAULT_NODES = {3: "mcb560", 5: "dat7014", 6: "dat7130", 7: "i7231d"}
DEFAULT_BITRATE = 500_000


@dataclass
class SimNetwork:
    profiles: dict[int, DeviceProfile]
    bitrate: int = DEFAULT_BITRATE
    config: dict[int, list[tuple[int, int, int]]] = field(default_factory=dict)


def default_network() -> dict[int, DeviceProfile]:
    return {node: load_builtin(key) for node, key in DEFAULT_NODES.items()}


def load_network(path: str | Path) -> SimNetwork:
    """The nodes of a network file; InputError when a node has no device or EDS."""
    from cananalyze.config.netfile import load_network as read_netfile

    spec = read_netfile(path)
    profiles: dict[int, DeviceProfile] = {}
    config: dict[int, list[tuple[int, int, int]]] = {}
    for node, ns in sorted(spec.nodes.items()):
        if ns.profile is None:
            raise InputError(f"{path}: node {node}: the simulator needs its device or eds")
        profiles[node] = ns.profile
        config[node] = list(ns.writes)
    if not profiles:
        raise InputError(f"{path}: no nodes to simulate")
    return SimNetwork(profiles, spec.bitrate or DEFAULT_BITRATE, config)
