"""What was configured: the values rules check against, behind a small interface.

Rules ask a ConfigSource, never a file or a profile directly, so the network
model (which follows SDO writes over time) can stand in through a thin adapter.
Every method takes the time at which the value is wanted and returns None when
nothing is known: a rule then skips what it cannot judge.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from ..network.pdo_map import PdoConfig


class ConfigSource(Protocol):
    def heartbeat_ms(self, node: int, t: float) -> float | None:
        """Producer heartbeat time 0x1017 (0 = disabled)."""

    def heartbeat_consumers(self, node: int, t: float) -> dict[int, float]:
        """0x1016 of consumer `node`: producer node -> consumer time in ms."""

    def guarding(self, node: int, t: float) -> tuple[float, int] | None:
        """(guard time 0x100C in ms, life time factor 0x100D)."""

    def sync_period_us(self, t: float) -> float | None:
        """Communication cycle period 0x1006."""

    def sync_window_us(self, t: float) -> float | None:
        """Synchronous window length 0x1007 (0 = none)."""

    def pdo_params(self, cob_id: int, t: float) -> tuple[int, PdoConfig] | None:
        """(node, PdoConfig) of the PDO using this COB-ID."""

    def emcy_inhibit_100us(self, node: int, t: float) -> float | None:
        """EMCY inhibit time 0x1015, in 100 us."""

    def known_cob_ids(self) -> set[int]:
        """Identifiers the network file declares as expected (non-CANopen traffic)."""


class FileConfig:
    """Values from a network file, filling gaps from each node's device profile (EDS/DCF).

    Static in time: the file says what is configured for the whole log.
    """

    def __init__(self, network: dict | None = None, base: Path | None = None) -> None:
        network = network or {}
        self.nodes: dict[int, dict] = {
            int(k): dict(v or {}) for k, v in (network.get("nodes") or {}).items()
        }
        self.sync: dict = dict(network.get("sync") or {})
        self.extra_ids: set[int] = {int(x) for x in network.get("known_cob_ids") or []}
        self._pdos: dict[int, tuple[int, PdoConfig]] = {}
        self._profiles: dict[int, object] = {}
        for node, spec in self.nodes.items():
            prof = spec.get("profile")
            if prof:
                self._profiles[node] = _load_profile(str(prof), node, base)
                for p in self._profiles[node].pdos(node):
                    if p.valid:
                        self._pdos[p.cob_id] = (node, p)
        for cob, spec in (network.get("pdos") or {}).items():
            self._pdos[int(cob)] = (
                int(spec["node"]),
                _pdo_from_spec(int(cob), spec, self._pdos.get(int(cob))),
            )

    def _od(self, node: int, key: str, index: int, sub: int = 0) -> float | None:
        v = self.declared(node, key)
        return v if v is not None else self.default(node, index, sub)

    def declared(self, node: int, key: str) -> float | None:
        """A value the user wrote down for this node (an override), or None."""
        spec = self.nodes.get(node)
        if spec is None or key not in spec:
            return None
        return float(spec[key])

    def default(self, node: int, index: int, sub: int = 0) -> float | None:
        """The node's device profile value (DCF value, else EDS default), or None."""
        prof = self._profiles.get(node)
        if prof is None:
            return None
        v = prof.value(index, sub, node)
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None

    def heartbeat_ms(self, node: int, t: float) -> float | None:
        return self._od(node, "heartbeat_ms", 0x1017)

    def heartbeat_consumers(self, node: int, t: float) -> dict[int, float]:
        spec = self.nodes.get(node) or {}
        return {int(k): float(v) for k, v in (spec.get("heartbeat_consumer") or {}).items()}

    def guarding(self, node: int, t: float) -> tuple[float, int] | None:
        guard = self._od(node, "guard_time_ms", 0x100C)
        factor = self._od(node, "life_time_factor", 0x100D)
        if not guard:
            return None
        return guard, int(factor or 0)

    def sync_period_us(self, t: float) -> float | None:
        v = self.sync.get("period_us")
        return float(v) if v else None

    def sync_window_us(self, t: float) -> float | None:
        v = self.sync.get("window_us")
        return float(v) if v else None

    def pdo_params(self, cob_id: int, t: float) -> tuple[int, PdoConfig] | None:
        return self._pdos.get(cob_id)

    def emcy_inhibit_100us(self, node: int, t: float) -> float | None:
        return self._od(node, "emcy_inhibit_100us", 0x1015)

    def known_cob_ids(self) -> set[int]:
        return self.extra_ids


def _load_profile(name: str, node: int, base: Path | None):
    from ..errors import InputError
    from ..network.profile import BUILTIN_KEYS, load_builtin, load_eds

    if name in BUILTIN_KEYS:
        return load_builtin(name)
    path = Path(name)
    if base is not None and not path.is_absolute():
        path = base / path
    if not path.exists():
        raise InputError(
            f"node {node}: profile {name!r} is neither a built-in ({', '.join(BUILTIN_KEYS)}) nor a file"
        )
    return load_eds(path, node)


def _pdo_from_spec(cob: int, spec: dict, base: tuple[int, PdoConfig] | None) -> PdoConfig:
    old = base[1] if base else None
    cfg = PdoConfig(
        direction=spec.get("direction", old.direction if old else "tx"),
        number=int(spec.get("number", old.number if old else 0)),
        cob_id=cob,
        valid=True,
        transmission_type=int(spec.get("transmission_type", old.transmission_type if old else 255)),
        inhibit_time=int(spec.get("inhibit_100us", old.inhibit_time if old else 0)),
        event_timer=int(spec.get("event_timer_ms", old.event_timer if old else 0)),
        mapping=list(old.mapping) if old else [],
    )
    if "length" in spec:
        cfg.mapping = []
        cfg.length_override = int(spec["length"])  # type: ignore[attr-defined]
    return cfg


def pdo_length_bytes(cfg: PdoConfig) -> int | None:
    """Mapped length in bytes, or None when the mapping is unknown."""
    over = getattr(cfg, "length_override", None)
    if over is not None:
        return over
    if not cfg.mapping:
        return None
    return (cfg.bits + 7) // 8
