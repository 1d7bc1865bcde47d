"""Each node's NMT state over time, from heartbeats, guard responses, boot-ups and NMT commands.

Heartbeats are bulk traffic, so state changes are found columnar (a heartbeat whose
state byte differs from that node's previous one); NMT commands and boot-ups are
rare and handled one by one.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.senders import senders
from cananalyze.core.records import DecodedBatch
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

    def _add(self, node: int, t: float, state: int, source: str) -> None:
        ts = self.times.setdefault(node, [])
        ss = self.states.setdefault(node, [])
        if ss and ss[-1] == state and source != "bootup":
            return
        ts.append(t)
        ss.append(state)
        self.sources.setdefault(node, []).append(source)
        self._last[node] = state

    def update(self, batch: DecodedBatch, ctx=None) -> None:
        """`ctx`: the batch's checks.rule.Context, whose heartbeat gap table holds the
        heartbeat rows already grouped by node (used when the batch has no guard
        response) and which finds each service's rows once for every rule."""
        svc = batch.service
        fb = batch.frames
        heard = senders(batch)
        self._heard[heard[heard < 128]] = True

        def rows(s: Service) -> np.ndarray:
            return np.flatnonzero(svc == s) if ctx is None else ctx.rows(s)

        events: list[tuple[float, int, int, str]] = []
        if ctx is not None and rows(Service.GUARD_RESPONSE).size == 0:
            heartbeats = ctx.gaps("heartbeat")
            n, r = heartbeats.key, heartbeats.row
            s = (fb.data[r, 0] & STATE_MASK).astype(np.int16)
        else:
            report = np.flatnonzero((svc == Service.HEARTBEAT) | (svc == Service.GUARD_RESPONSE))
            nodes = batch.node[report].astype(np.intp)
            state = (fb.data[report, 0] & STATE_MASK).astype(np.int16)
            order = np.argsort(nodes, kind="stable")
            n, s, r = nodes[order], state[order], report[order]
        if r.size:
            prev = np.empty_like(s)
            prev[1:] = s[:-1]
            first = np.ones(n.size, bool)
            first[1:] = n[1:] != n[:-1]
            prev[first] = self._last[n[first]]
            change = np.flatnonzero(s != prev)
            for i in change.tolist():
                events.append((float(fb.t[r[i]]), int(n[i]), int(s[i]), "heartbeat"))
        for i in rows(Service.BOOTUP).tolist():
            events.append((float(fb.t[i]), int(batch.node[i]), PRE_OPERATIONAL, "bootup"))
        for i in rows(Service.NMT).tolist():
            if fb.dlc[i] < 2:
                continue
            state = COMMAND_STATE.get(int(fb.data[i, 0]))
            if state is None:
                continue
            target = int(fb.data[i, 1])
            if 0 <= target < 128:
                events.append((float(fb.t[i]), target, state, "nmt"))
        events.sort(key=lambda e: e[0])
        for t, node, state, source in events:
            for n in list(self.times) if node == ALL_NODES else [node]:  # all known so far
                self._add(n, t, state, source)

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
