"""What the user declares about the network before the log says anything.

Filled from `--device`, `--eds` and `--network FILE`; the network model starts
from it. Writes are (index, subindex, value) applied on top of the profile's
defaults, exactly as an SDO download would be.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .profile import DeviceProfile


@dataclass
class NodeSpec:
    profile: DeviceProfile | None = None
    how: str = "unknown"  # "user --device", "user --eds", "network file"
    writes: list[tuple[int, int, int]] = field(default_factory=list)
    sdo_channels: list[tuple[int, int]] = field(default_factory=list)  # (request, response)


@dataclass
class NetworkSpec:
    nodes: dict[int, NodeSpec] = field(default_factory=dict)
    bitrate: int | None = None
    source: str | None = None  # the network file, for messages

    def node(self, node_id: int) -> NodeSpec:
        return self.nodes.setdefault(node_id, NodeSpec())
