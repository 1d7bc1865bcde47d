"""ConfigSource over the network model: values written by SDO in the log, at their time.

Falls back to another ConfigSource (the rules file's `network:` section and the
profiles) for whatever the log never wrote.
"""

from __future__ import annotations

from ..network.pdo_map import PdoConfig
from .config import ConfigSource


class ModelConfig:
    def __init__(self, model, fallback: ConfigSource) -> None:
        self.model = model
        self.fallback = fallback

    def _value(self, node: int, index: int, sub: int, t: float) -> int | None:
        v = self.model.value_at(node, index, sub, t)
        return v if isinstance(v, int) else None

    def heartbeat_ms(self, node: int, t: float) -> float | None:
        v = self._value(node, 0x1017, 0, t)
        return float(v) if v is not None else self.fallback.heartbeat_ms(node, t)

    def heartbeat_consumers(self, node: int, t: float) -> dict[int, float]:
        out = dict(self.fallback.heartbeat_consumers(node, t))
        for sub in range(1, 128):
            v = self._value(node, 0x1016, sub, t)
            if v is None:
                if sub > 8:
                    break
                continue
            producer, ms = (v >> 16) & 0xFF, v & 0xFFFF
            if producer and ms:
                out[producer] = float(ms)
        return out

    def guarding(self, node: int, t: float) -> tuple[float, int] | None:
        guard = self._value(node, 0x100C, 0, t)
        factor = self._value(node, 0x100D, 0, t)
        if guard is None and factor is None:
            return self.fallback.guarding(node, t)
        base = self.fallback.guarding(node, t) or (0.0, 0)
        guard_ms = float(guard) if guard is not None else base[0]
        return (guard_ms, int(factor if factor is not None else base[1])) if guard_ms else None

    def _any_node(self, index: int, t: float) -> int | None:
        for change in reversed(self.model.history):
            if change.object == (index, 0) and change.t <= t and isinstance(change.value, int):
                return change.value
        return None

    def sync_period_us(self, t: float) -> float | None:
        v = self._any_node(0x1006, t)
        return float(v) if v else self.fallback.sync_period_us(t)

    def sync_window_us(self, t: float) -> float | None:
        v = self._any_node(0x1007, t)
        return float(v) if v else self.fallback.sync_window_us(t)

    def pdo_params(self, cob_id: int, t: float) -> tuple[int, PdoConfig] | None:
        b = self.model.binding(cob_id)
        if b is not None and b.config.mapping:
            return b.node, b.config
        return self.fallback.pdo_params(cob_id, t)

    def emcy_inhibit_100us(self, node: int, t: float) -> float | None:
        v = self._value(node, 0x1015, 0, t)
        return float(v) if v is not None else self.fallback.emcy_inhibit_100us(node, t)

    def known_cob_ids(self) -> set[int]:
        return self.fallback.known_cob_ids()
