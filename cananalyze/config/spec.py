"""What the user declares about the network before the log says anything.

Filled from `--network FILE`, the rules file's `network:` section, `--device` and
`--eds` (pipeline.network_spec); the network model starts from it. Writes are
(index, subindex, value) applied on top of the profile's defaults, exactly as an SDO
download would be, so the model holds the user's values as object values too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cananalyze.devices.profile import DeviceProfile


@dataclass
class NodeSpec:
    profile: DeviceProfile | None = None
    how: str = "unknown"  # "user --device", "user --eds", "network file", "rules file"
    writes: list[tuple[int, int, int]] = field(default_factory=list)
    sdo_channels: list[tuple[int, int]] = field(default_factory=list)  # (request, response)
    # expected length in bytes of a PDO ("tx"/"rx", number) while its mapping is unknown
    pdo_lengths: dict[tuple[str, int], int] = field(default_factory=dict)
    name: str | None = None  # the file's label for the node (not used by the analysis)
    canopen_fd: bool = False  # CiA 1301: its SDO COB-IDs carry USDO frames
    # (index, subindex) -> {name, unit, scale, offset}: how to show a mapped object
    signals: dict[tuple[int, int], dict] = field(default_factory=dict)


@dataclass
class NetworkSpec:
    nodes: dict[int, NodeSpec] = field(default_factory=dict)
    bitrate: int | None = None
    source: str | None = None  # the network file, for messages
    # objects of the bus as a whole: SYNC period 0x1006 and window 0x1007 from [sync]
    bus_writes: list[tuple[int, int, int]] = field(default_factory=list)
    known_cob_ids: set[int] = field(default_factory=set)  # expected non-CANopen identifiers
    canopen_fd: bool = False  # CiA 1301: the whole network is CANopen FD (USDO, no SDO)

    def node(self, node_id: int) -> NodeSpec:
        return self.nodes.setdefault(node_id, NodeSpec())
