"""Each node's NMT state over time, from heartbeats, guard responses, boot-ups and NMT commands.

The one computation of it: the checks judge by it, and the event log's `nmt_state`
rows (and so the nodes table's `last_state`, the report's timeline) are its changes.

Heartbeats are bulk traffic, so state changes are found columnar (a heartbeat whose
state byte differs from that node's previous one); NMT commands and boot-ups are
rare and handled one by one.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.decode.senders import SENT, senders
from cananalyze.protocol.nmt import (
    ALL_NODES,
    COMMAND_STATE,
    PRE_OPERATIONAL,
    STATE_MASK,
    state_name,
)
from cananalyze.protocol.services import Service


class NmtStates:
    def __init__(self) -> None:
        self.times: dict[int, list[float]] = {}
        self.states: dict[int, list[int]] = {}
        self.sources: dict[int, list[str]] = {}
        self._last = np.full(128, -1, np.int16)
        self._heard = np.zeros(128, bool)  # nodes that sent a frame themselves
        self._arrays: dict[int, tuple] = {}  # state_at's, per node

    def _add(self, node: int, t: float, state: int, source: str) -> bool:
        ts = self.times.setdefault(node, [])
        ss = self.states.setdefault(node, [])
        if ss and ss[-1] == state and source != "bootup":
            return False
        ts.append(t)
        ss.append(state)
        self.sources.setdefault(node, []).append(source)
        self._last[node] = state
        return True

    def update(self, batch: DecodedBatch, ctx=None) -> None:
        """Follow one batch (the checks). `ctx`: the batch's checks.rule.Context, whose
        heartbeat gap table holds the heartbeat rows already grouped by node (used when
        the batch has no guard response) and which finds each service's rows once for
        every rule."""
        svc = batch.service
        heard = senders(batch)
        self._heard[heard[heard < 128]] = True

        def pick(s: Service) -> np.ndarray:
            return np.flatnonzero(svc == s) if ctx is None else ctx.rows(s)

        grouped = None
        if ctx is not None and pick(Service.GUARD_RESPONSE).size == 0:
            heartbeats = ctx.gaps("heartbeat")
            grouped = heartbeats.key, heartbeats.row
        self._follow(batch, pick, grouped)

    def changes(
        self, batch: DecodedBatch, rows: np.ndarray, channel: int
    ) -> list[tuple[int, float, int, int]]:
        """Follow these rows of a batch (the event log's NMT, heartbeat, guarding and
        boot-up rows of one bus, `channel`) and give the
        changes they made, as (row, t, node, state), of nodes heard by then: a node a
        master only commanded (a reset sent to every node-ID) has no state to tell."""
        heard_from = np.where(self._heard, -1, np.iinfo(np.int64).max)  # first row heard
        new = senders(batch)
        new = new[(new < 128) & ~self._heard[np.minimum(new, 127)]]
        if new.size:  # nodes heard first in this batch: from which row (rare)
            svc = batch.service
            own = np.flatnonzero(SENT[svc] & np.isin(batch.node, new))
            own = own[batch.frames.channel[own] == channel]
            nodes, first = np.unique(batch.node[own], return_index=True)
            heard_from[nodes] = own[first]
            self._heard[nodes] = True
        made = self._follow(batch, lambda s: rows[batch.service[rows] == s], None)
        return [(row, t, n, v) for row, t, n, v in made if heard_from[n] <= row]

    def _follow(self, batch: DecodedBatch, pick, grouped) -> list[tuple[int, float, int, int]]:
        """Apply the batch's state reports and commands in time (then file) order; the
        changes made. Heartbeats are bulk: only those whose state differs from the
        node's previous report, or that come first after a command to the node, can
        change its state; those and the commands are then applied one by one, so the
        result does not depend on where batches end."""
        fb = batch.frames
        if grouped is not None:
            n, r = grouped
        else:
            report = np.concatenate((pick(Service.HEARTBEAT), pick(Service.GUARD_RESPONSE)))
            report.sort()
            nodes = batch.node[report].astype(np.intp)
            order = np.argsort(nodes, kind="stable")
            n, r = nodes[order], report[order]
        s = (fb.data[r, 0] & STATE_MASK).astype(np.int16)
        commands: list[tuple[float, int, int, int, str]] = []  # t, row, node, state, source
        for i in pick(Service.BOOTUP).tolist():
            commands.append((float(fb.t[i]), i, int(batch.node[i]), PRE_OPERATIONAL, "bootup"))
        for i in pick(Service.NMT).tolist():
            if fb.dlc[i] < 2:
                continue
            state = COMMAND_STATE.get(int(fb.data[i, 0]))
            if state is None:
                continue
            target = int(fb.data[i, 1])
            if 0 <= target < 128:
                commands.append((float(fb.t[i]), i, target, state, "nmt"))
        events = list(commands)
        if r.size:
            prev = np.empty_like(s)
            prev[1:] = s[:-1]
            first = np.ones(n.size, bool)
            first[1:] = n[1:] != n[:-1]
            prev[first] = self._last[np.clip(n[first], 0, 127)]
            may = s != prev
            if commands:  # the first report after each command may undo it
                starts = np.flatnonzero(first)
                ends = np.append(starts[1:], n.size)
                spans = zip(starts.tolist(), ends.tolist(), strict=True)
                seg = dict(zip(n[starts].tolist(), spans, strict=True))
                for _, row, node, _, _ in commands:
                    for a, e in seg.values() if node == ALL_NODES else [seg.get(node, (0, 0))]:
                        j = a + int(np.searchsorted(r[a:e], row))
                        if j < e:
                            may[j] = True
            for i in np.flatnonzero(may).tolist():
                events.append((float(fb.t[r[i]]), int(r[i]), int(n[i]), int(s[i]), "heartbeat"))
        # by time, and in file order at one time (a log without times: every frame at 0)
        events.sort(key=lambda e: (e[0], e[1]))
        made: list[tuple[int, float, int, int]] = []
        for t, row, node, state, source in events:
            for k in list(self.times) if node == ALL_NODES else [node]:  # all known so far
                if 0 <= k < 128 and self._add(k, t, state, source):
                    made.append((row, t, k, state))
        return made

    def state_at(self, node: int, t: np.ndarray) -> np.ndarray:
        """State in effect at each time (-1 unknown), by binary search over the changes."""
        ts = self.times.get(node)
        if not ts:
            return np.full(np.shape(t), -1, np.int16)
        _, times, states, _ = self._cached(node, ts)
        idx = np.searchsorted(times, t, side="right") - 1
        return np.where(idx >= 0, states[np.maximum(idx, 0)], -1).astype(np.int16)

    def steady_state(self, node: int, t_lo: float, t_hi: float) -> int | None:
        """The state `state_at` gives at every time in [t_lo, t_hi] when no change falls
        inside (-1 unknown), else None: a batch's rows of a node then need no lookup each."""
        ts = self.times.get(node)
        if not ts:
            return -1
        _, times, states, ordered = self._cached(node, ts)
        if not (ordered and t_lo <= t_hi):
            return None
        lo, hi = (np.searchsorted(times, [t_lo, t_hi], side="right") - 1).tolist()
        if lo != hi:
            return None
        return int(states[lo]) if lo >= 0 else -1

    def _cached(self, node: int, ts: list[float]) -> tuple:
        """(length, times, states, times in order) of a node as arrays."""
        cached = self._arrays.get(node)
        if cached is None or cached[0] != len(ts):  # the lists only grow: length says stale
            times = np.asarray(ts)
            cached = self._arrays[node] = (
                len(ts),
                times,
                np.asarray(self.states[node], np.int16),
                bool(np.all(times[1:] >= times[:-1])),
            )
        return cached

    def timeline(self) -> dict[int, list[tuple[float, str, str]]]:
        """Each node's states, of the nodes that sent a frame: a node the master only
        commanded (a reset sent to every node-ID in turn) never said it was there."""
        return {
            n: [
                (t, state_name(s), src)
                for t, s, src in zip(self.times[n], self.states[n], self.sources[n], strict=True)
            ]
            for n in sorted(self.times)
            if self._heard[n]
        }
