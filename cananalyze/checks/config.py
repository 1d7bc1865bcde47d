"""What was configured: the values rules check against, behind a small interface.

Rules ask a ConfigSource, never a file or a profile directly. Every method takes the
time at which the value is wanted: the answer is the one in force at that moment
(docs/network-file.md, "Precedence"). None means nothing is known (a rule then skips
what it cannot judge); 0 where CiA 301 says 0 disables the function means off.
`changes` says when answers may change, so a rule can ask once per stretch of frames
under one configuration instead of once per frame.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from cananalyze.protocol.pdo_map import PdoConfig
from cananalyze.protocol.srdo import SrdoConfig


class ConfigSource(Protocol):
    def configured_nodes(self) -> list[int]:
        """Nodes whose configuration anything says (declared, or shown by the log)."""

    def raw(self, node: int, index: int, sub: int, t: float) -> int | None:
        """An object's value in force at t with its flag bits (None: nothing says)."""

    def value_time(self, node: int, index: int, sub: int, t: float) -> float | None:
        """When the log showed the value in force at t (None: declared or a default)."""

    def pdo_numbers(self, node: int) -> list[tuple[int, int]]:
        """(communication, mapping) indices of the PDOs anything says something of."""

    def points_from(self, k: int) -> list[tuple[float, int, int]]:
        """(t, node, index) points where an answer may change, from the k-th on (index
        -1: all of the node, node 0: every node); the list only grows."""

    def heartbeat_ms(self, node: int, t: float) -> float | None:
        """Producer heartbeat time 0x1017 (0 = disabled, None = unknown)."""

    def heartbeat_consumers(self, node: int, t: float) -> dict[int, float]:
        """0x1016 of consumer `node`: producer node -> consumer time in ms (enabled only)."""

    def guarding(self, node: int, t: float) -> tuple[float, int] | None:
        """(guard time 0x100C in ms, life time factor 0x100D); None: off or unknown."""

    def sync_period_us(self, t: float) -> float | None:
        """Communication cycle period 0x1006 (0 = no SYNC)."""

    def sync_window_us(self, t: float) -> float | None:
        """Synchronous window length 0x1007 (0 = none)."""

    def pdo_params(self, cob_id: int, t: float) -> tuple[int, PdoConfig] | None:
        """(node, PdoConfig) of the PDO using this COB-ID."""

    def srdo_params(self, cob_id: int, t: float) -> tuple[SrdoConfig, bool] | None:
        """The SRDO using this COB-ID at t, and whether as its inverted frame."""

    def emcy_inhibit_100us(self, node: int, t: float) -> float | None:
        """EMCY inhibit time 0x1015, in 100 us (0 = none)."""

    def origin(self, node: int | None, index: int, sub: int, t: float, t0: float = 0.0) -> str:
        """Where the value in force at t comes from ("0x1017 written at +1.000 s")."""

    def consumer_origin(self, consumer: int, producer: int, t: float, t0: float = 0.0) -> str:
        """Where the consumer's 0x1016 entry for `producer` in force at t comes from."""

    def known_cob_ids(self) -> set[int]:
        """Identifiers the network file declares as expected (non-CANopen traffic)."""

    def declared_nodes(self) -> set[int]:
        """Node-IDs the user declared (network or rules file, --device, --eds)."""

    def changes(self, node: int | None, first: int, last: int) -> np.ndarray:
        """Times (ascending) at which an answer about objects first..last of `node`
        (None: of any node) may change: a value the log showed, a reset."""

    def pdo_changes(self) -> np.ndarray:
        """Times (ascending) at which any PDO's parameters or COB-ID changed."""
