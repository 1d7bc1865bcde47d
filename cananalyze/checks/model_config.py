"""ConfigSource over the network model: what the rules expect, at the time they ask.

The model holds the user's declarations (network file, rules file `network:`,
--device/--eds) as its starting state and follows the log, so one rule answers every
question (docs/network-file.md, "Precedence"): the last value the log showed for the
object at or before t (an SDO write or read, since the node's last reset), else the
user's, else the device profile's.

Where CiA 301 says 0 disables a function (heartbeat 0x1017, guard time 0x100C, SYNC
0x1006/0x1007, EMCY inhibit 0x1015, a 0x1016 entry, PDO inhibit time and event timer),
a 0 from the log or the user means off. A 0 that is only the profile's is "unknown":
many EDS files default 0x1017 to 0 while the device is configured otherwise.
"""

from __future__ import annotations

import numpy as np

from cananalyze.config.timeline import EVERY_NODE
from cananalyze.core.finding import rel_time
from cananalyze.decode.model import NetworkModel
from cananalyze.protocol.pdo_map import PdoConfig, split_cob_id
from cananalyze.protocol.srdo import SrdoConfig


class ModelConfig:
    def __init__(self, model: NetworkModel) -> None:
        self.model = model
        self._changes: dict[tuple, tuple[int, np.ndarray]] = {}
        self._pdos: dict[int, set[int]] | None = None  # node -> PDO communication indices
        self._pdos_seen = 0  # of the timeline's history

    def _value(self, node: int, index: int, sub: int, t: float) -> int | None:
        k = self.model.known(node, index, sub, t)
        if k is None or (k.value == 0 and k.source == "profile"):
            return None
        return k.value

    def origin(self, node: int | None, index: int, sub: int, t: float, t0: float = 0.0) -> str:
        """Where the value of an object in force at t comes from, in a finding's words:
        "0x1017 written at +12.300 s", "network file", "profile default" (node None:
        a bus-wide object, 0x1006/0x1007)."""
        tl = self.model.timeline
        if node is None:
            change = tl.latest(index, t)
            entry = None if change is None else (change.t, 0, change)
            declared = (index, 0) in self.model._bus_file
        else:
            entry = tl.last(node, index, sub, t)
            declared = (node, index, sub) in self.model._file
        obj = f"0x{index:04X}" if sub == 0 else f"0x{index:04X}:{sub}"
        if entry is not None:
            c = entry[2]
            how = "read back" if c.how == "read" else "written"
            where = "" if node is None or c.node == node else f" on node {c.node}"
            return f"{obj} {how}{where} at {rel_time(c.t, t0)}"
        if declared:
            return (
                f"{obj} in the network file"
                if self.model.spec.source
                else (f"{obj} in the rules file's network:")
            )
        return f"{obj} profile default"

    def consumer_origin(self, consumer: int, producer: int, t: float, t0: float = 0.0) -> str:
        """Where `consumer`'s 0x1016 entry for `producer` in force at t comes from."""
        for sub in self.model.subindices(consumer, 0x1016):
            if ((self._value(consumer, 0x1016, sub, t) or 0) >> 16) & 0x7F == producer:
                return self.origin(consumer, 0x1016, sub, t, t0)
        return "0x1016"

    def configured_nodes(self) -> list[int]:
        """Nodes whose configuration anything says: declared, or shown by the log."""
        return sorted((set(self.model.nodes) | self.model.timeline.nodes()) - {EVERY_NODE})

    def raw(self, node: int, index: int, sub: int, t: float) -> int | None:
        """An object's value in force at t as it stands (a COB-ID word with its flag bits),
        a profile's 0 included; None: nothing says. Assumed CiA 4xx defaults are not
        values: the generic profile guesses a device it never saw."""
        k = self.model.known(node, index, sub, t)
        if k is None:
            return None
        if k.source == "profile":
            cfg = self.model.nodes.get(node)
            if cfg is not None and cfg.profile is not None and cfg.profile.generic:
                return None
        return k.value

    def value_time(self, node: int, index: int, sub: int, t: float) -> float | None:
        """When the log showed the value in force at t (None: a declared or default one)."""
        entry = self.model.timeline.last(node, index, sub, t)
        return None if entry is None else entry[0]

    def pdo_numbers(self, node: int) -> list[tuple[int, int]]:
        """(communication index, mapping index) of every PDO of a node that the user, the
        log or the node's profile says anything of (the log's, followed as it grows)."""
        if self._pdos is None:
            self._pdos = {}
            for n, index, _ in self.model._file:
                self._add_pdo(n, index)
        history = self.model.timeline.history
        for change in history[self._pdos_seen :]:
            self._add_pdo(change.node, change.object[0])
        self._pdos_seen = len(history)
        out = set(self._pdos.get(node, ()))
        cfg = self.model.nodes.get(node)
        if cfg is not None:
            out.update((0x1800 if d == "tx" else 0x1400) + n - 1 for d, n in cfg.pdos)
        return [(c, c + 0x200) for c in sorted(out)]

    def pdo_cob_ids(self, node: int, t: float) -> list[tuple[int, int, int, bool]]:
        """(communication index, mapping index, COB-ID word, valid) of each PDO of a node
        whose COB-ID anything gives at t: who produces (TPDO) or consumes (RPDO) which
        COB-ID, as the consistency rule and the report's network page read it."""
        out = []
        for comm, mapping in self.pdo_numbers(node):
            value = self.raw(node, comm, 1, t)
            if value is not None:
                out.append((comm, mapping, value, split_cob_id(value)[1]))
        return out

    def _add_pdo(self, node: int, index: int) -> None:
        if 0x1400 <= index <= 0x1BFF:
            self._pdos.setdefault(node, set()).add(index & ~0x200)  # type: ignore[union-attr]

    def points_from(self, k: int) -> list[tuple[float, int, int]]:
        """The (t, node, index) points at which an answer may have changed, from the k-th
        on (index -1: everything of the node; node 0: every node); the list only grows."""
        return self.model.points[k:]

    def heartbeat_ms(self, node: int, t: float) -> float | None:
        v = self._value(node, 0x1017, 0, t)
        return None if v is None else float(v)

    def heartbeat_consumers(self, node: int, t: float) -> dict[int, float]:
        out: dict[int, float] = {}
        for sub in self.model.subindices(node, 0x1016):
            v = self._value(node, 0x1016, sub, t)
            producer, ms = ((v or 0) >> 16) & 0x7F, (v or 0) & 0xFFFF
            if producer and ms:
                out[producer] = float(ms)
        return out

    def guarding(self, node: int, t: float) -> tuple[float, int] | None:
        guard = self._value(node, 0x100C, 0, t)
        if not guard:
            return None
        return float(guard), int(self._value(node, 0x100D, 0, t) or 0)

    def _bus(self, index: int, t: float) -> float | None:
        k = self.model.bus_known(index, t)
        if k is None or (k.value == 0 and k.source == "profile"):
            return None
        return float(k.value)

    def sync_period_us(self, t: float) -> float | None:
        return self._bus(0x1006, t)

    def sync_window_us(self, t: float) -> float | None:
        return self._bus(0x1007, t)

    def pdo_params(self, cob_id: int, t: float) -> tuple[int, PdoConfig] | None:
        b = self.model.binding_at(cob_id, t)
        return None if b is None else (b.node, b.config)

    def srdo_params(self, cob_id: int, t: float) -> tuple[SrdoConfig, bool] | None:
        return self.model.srdo_at(cob_id, t)

    def emcy_inhibit_100us(self, node: int, t: float) -> float | None:
        v = self._value(node, 0x1015, 0, t)
        return None if v is None else float(v)

    def tpdo_shows_every_change(self, node: int, number: int, t: float) -> bool:
        """Whether TPDO `number` of a node sends each change of what it maps at t: event
        driven (transmission type 254/255 known, not assumed) and no inhibit time."""
        comm = 0x1800 + number - 1
        ttype = self.model.known(node, comm, 2, t)
        if ttype is None or ttype.value not in (254, 255):
            return False
        inhibit = self.model.known(node, comm, 3, t)
        return inhibit is None or inhibit.value == 0

    def known_cob_ids(self) -> set[int]:
        return self.model.spec.known_cob_ids

    def declared_nodes(self) -> set[int]:
        return set(self.model.spec.nodes)

    def changes(self, node: int | None, first: int, last: int) -> np.ndarray:
        points = self.model.points
        key = (node, first, last)
        cached = self._changes.get(key)
        if cached is None or cached[0] != len(points):  # points only grow: length says stale
            times = [
                t
                for t, n, index in points
                if (node is None or n == node or n == EVERY_NODE)
                and (index == -1 or first <= index <= last)
            ]
            # unique: a reset to all nodes marks each known node and every node at one time
            cached = self._changes[key] = (len(points), np.unique(np.asarray(times, np.float64)))
        return cached[1]

    def reset_commands(self, node: int) -> np.ndarray:
        """Sorted times of the NMT reset commands to a node, its own and those to all."""
        commands = self.model.timeline.commands
        mine, every = commands.get(node, []), commands.get(EVERY_NODE, [])
        key = ("reset", node)
        cached = self._changes.get(key)
        if cached is None or cached[0] != len(mine) + len(every):
            times = np.unique(np.asarray(mine + every, np.float64))
            cached = self._changes[key] = (len(mine) + len(every), times)
        return cached[1]

    def pdo_changes(self) -> np.ndarray:
        return np.asarray(self.model.binding_times[1:], np.float64)
