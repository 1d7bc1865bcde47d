"""The configuration values a log showed, object by object, and the resets that end them.

The network model asks it what the log says an object held at a time: the last value
an SDO write or read showed at or before that time, unless the node was reset since
(a boot-up or an NMT reset command returns a node to its declared values; a reset
communication only for 0x1000-0x1FFF, CiA 301). It also keeps the times at which an
answer changed, so the checks can ask once per stretch of frames under one value.
"""

from __future__ import annotations

from dataclasses import dataclass

# A node's boot-up this long after an NMT reset command addressed to it answers that
# command (the reset is taken at the command); a later one is a reset of its own.
RESET_ANSWER_S = 10.0


@dataclass(frozen=True)
class ConfigChange:
    t: float
    node: int
    object: tuple[int, int]  # (index, subindex)
    value: int
    how: str = "write"  # "write": an SDO download, "read": an SDO upload (a read-back)


def _communication(index: int) -> bool:
    return 0x1000 <= index <= 0x1FFF


# the node of a point that concerns every node (NMT node-ID 0: "all nodes")
EVERY_NODE = 0


class Timeline:
    def __init__(self) -> None:
        self.history: list[ConfigChange] = []  # every value the log showed, in order
        # (t, node, index) where an answer changed; index -1: a reset or a new profile
        # (everything of the node may have changed); node EVERY_NODE: an NMT command to
        # all nodes, which resets nodes the log showed no value of too (heartbeat only)
        self.points: list[tuple[float, int, int]] = []
        # the values by object, with a sequence number to order them against resets
        self._values: dict[tuple[int, int, int], list[tuple[float, int, ConfigChange]]] = {}
        self._by_index: dict[int, set[int]] = {}  # index -> nodes with values of its sub 0
        self._subs: dict[tuple[int, int], set[int]] = {}  # (node, index) -> sub-indices seen
        self._resets: dict[int, list[tuple[float, int, bool]]] = {}  # (t, seq, comm only)
        self._pending: dict[int, float] = {}  # node -> time of an NMT reset command to it
        # node (EVERY_NODE: all) -> times of the NMT reset commands to it, in log order:
        # until its boot-up answers one, a node owes no heartbeat (CiA 301)
        self.commands: dict[int, list[float]] = {}
        self._since_reset: dict[int, list[ConfigChange]] = {}
        self._seq = 0

    def add(self, change: ConfigChange, changed: bool) -> None:
        """A value the log showed; `changed`: it differs from what was expected before."""
        self._seq += 1
        node, (index, sub) = change.node, change.object
        self.history.append(change)
        self._values.setdefault((node, index, sub), []).append((change.t, self._seq, change))
        self._since_reset.setdefault(node, []).append(change)
        self._subs.setdefault((node, index), set()).add(sub)
        if sub == 0:
            self._by_index.setdefault(index, set()).add(node)
        if changed:
            self.points.append((change.t, node, index))

    def mark(self, t: float, node: int) -> None:
        """Everything of a node may have changed (it got a profile)."""
        self.points.append((t, node, -1))

    def reset_all(self, t: float) -> None:
        """An NMT reset command to all nodes: every node's timers restart, also those of
        nodes the log showed no value of (known only by their heartbeat)."""
        self.commands.setdefault(EVERY_NODE, []).append(t)
        self.mark(t, EVERY_NODE)

    def reset(self, t: float, node: int, kind: str) -> bool:
        """One node's reset; False for the boot-up that answers an NMT reset command
        already taken (its timers start again, its values do not change again)."""
        if kind == "boot-up":
            sent = self._pending.pop(node, None)
            if sent is not None and t - sent <= RESET_ANSWER_S:
                self.mark(t, node)
                return False
        else:
            self._pending[node] = t
            self.commands.setdefault(node, []).append(t)
        comm_only = kind == "reset communication"
        self._seq += 1
        self._resets.setdefault(node, []).append((t, self._seq, comm_only))
        self.mark(t, node)
        self._since_reset[node] = [
            c
            for c in self._since_reset.get(node, ())
            if comm_only and not _communication(c.object[0])
        ]
        return True

    def nodes(self) -> set[int]:
        """Nodes the log showed a value of."""
        return {n for n, _, _ in self._values}

    def since_reset(self, node: int) -> list[ConfigChange]:
        """What the log changed on a node and still holds (replayed on a new profile)."""
        return self._since_reset.get(node, [])

    def last(self, node: int, index: int, subindex: int, t: float):
        """(t, seq, ConfigChange) of the value in force at t, None: none since a reset."""
        entries = self._values.get((node, index, subindex))
        if not entries:
            return None
        for entry in reversed(entries):
            if entry[0] <= t:
                break
        else:
            return None
        comm = _communication(index)
        for t_r, seq, comm_only in reversed(self._resets.get(node, ())):
            if t_r <= t and (comm or not comm_only):
                return entry if entry[1] > seq else None
        return entry

    def latest(self, index: int, t: float) -> ConfigChange | None:
        """The latest value in force at t of sub 0 of an object on any node."""
        found = None
        for node in self._by_index.get(index, ()):
            entry = self.last(node, index, 0, t)
            if entry is not None and (found is None or entry[:2] > found[:2]):
                found = entry
        return None if found is None else found[2]

    def subindices(self, node: int, index: int) -> set[int]:
        return self._subs.get((node, index), set())
