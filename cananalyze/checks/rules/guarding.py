"""Node guarding: request period vs 0x100C, life time, missing responses, toggle bit.

Guarding frames are rare (one RTR and one reply per node and guard time), so this
walks them one by one, each judged by the 0x100C/0x100D in force at its time.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.checks.spans import crossing
from cananalyze.protocol.nmt import toggle_of
from cananalyze.protocol.services import Service


class GuardingRule(Rule):
    name = "guarding"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "Node guarding is how master and node notice each other's loss; a late request or a "
        "missing or wrong reply makes one side take its life-guarding fault reaction; check "
        "0x100C/0x100D and the master's guarding schedule."
    )

    def __init__(self, response_timeout_ms: float = 100.0, **kw) -> None:
        super().__init__(**kw)
        self.timeout = response_timeout_ms / 1000.0
        self.req_t: dict[int, float] = {}
        self.pending: dict[int, float] = {}
        self.toggle: dict[int, int] = {}
        self.reported: set[tuple[int, float]] = set()  # (node, request t) tick() saw expire

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        rows = ctx.rows(Service.GUARD_REQUEST, Service.GUARD_RESPONSE, Service.BOOTUP)
        fb = b.frames
        for row in rows.tolist():
            node = int(b.node[row])
            t = float(fb.t[row])
            svc = b.service[row]
            if svc == Service.BOOTUP:
                self.toggle[node] = 1  # toggle restarts: the first reply after boot-up has 0
                self.req_t.pop(node, None)
                self.pending.pop(node, None)
                continue
            self.subjects.add(node)
            if svc == Service.GUARD_REQUEST:
                self._request(ctx, node, t, row)
            else:
                self.pending.pop(node, None)
                tog = toggle_of(int(fb.data[row, 0]))
                # a log that starts mid-session gives no reference for the first reply
                expect = 1 - self.toggle[node] if node in self.toggle else tog
                if tog != expect:
                    self.emit(
                        t,
                        node,
                        0x700 + node,
                        f"guard reply toggle bit {tog}, expected {expect}",
                        tog,
                        expect,
                        row=row,
                    )
                self.toggle[node] = tog

    def _request(self, ctx: Context, node: int, t: float, row: int) -> None:
        sent = self.pending.get(node)
        if sent is not None:
            self._no_reply(ctx, node, sent, row)
        prev = self.req_t.get(node)
        cfg = ctx.config.guarding(node, t) if ctx.timed else None
        if prev is not None and cfg:
            guard_ms, factor = cfg
            gap = t - prev
            # a gap across a new 0x100C (or 0x100D) is not judged against either value
            guard_moved = self._moved(ctx, node, 0x100C, prev, t)
            life_moved = guard_moved or self._moved(ctx, node, 0x100D, prev, t)
            if factor and not life_moved and gap * 1000 > guard_ms * factor + self.jitter_ms:
                if (node, prev) not in self.reported:  # tick() may have seen it while it lasted
                    self._life(ctx, node, prev, gap, guard_ms, factor, row)
            elif not guard_moved and abs(gap * 1000 - guard_ms) > self.slack(guard_ms):
                # the master's schedule, not the node's fault; faster only costs bus load
                faster = gap * 1000 < guard_ms
                self.emit(
                    t,
                    node,
                    0x700 + node,
                    f"guard request period {ms(gap)} ms, guard time is {guard_ms:g} ms"
                    + (" (faster: more bus load, no risk)" if faster else ""),
                    ms(gap),
                    guard_ms,
                    row=row,
                    severity="info" if faster else None,
                    basis=ctx.config.origin(node, 0x100C, 0, t, ctx.t0),
                )
        self.req_t[node] = t
        self.pending[node] = t

    def _life(self, ctx, node, prev, gap, guard_ms, factor, row=0, now=None, due=0.0) -> None:
        """Life time exceeded: no guard request for longer than 0x100C x 0x100D."""
        text = (
            f"life time exceeded: {ms(gap)} ms between guard requests"
            if now is None
            else f"life time exceeded: no guard request since {ctx.rel(prev)} ({ms(gap)} ms so far)"
        )
        self.emit(
            prev if now is None else now,
            node,
            0x700 + node,
            f"{text} > {guard_ms:g} ms x {factor}" + ("" if now is None else self.quiet(ctx, due)),
            ms(gap),
            guard_ms * factor,
            row=row,
            basis=ctx.config.origin(node, 0x100C, 0, prev, ctx.t0)
            + ", "
            + ctx.config.origin(node, 0x100D, 0, prev, ctx.t0),
        )

    def tick(self, ctx: Context, now: float) -> None:
        """Live: a node whose guard requests stopped past its life time, reported once."""
        for node, prev in sorted(self.req_t.items()):
            if (node, prev) in self.reported:
                continue
            cfg = ctx.config.guarding(node, prev)
            if not cfg or not cfg[1] or self._moved(ctx, node, 0x100C, prev, now):
                continue
            guard_ms, factor = cfg
            if (now - prev) * 1000 > guard_ms * factor + self.jitter_ms:
                self.reported.add((node, prev))
                due = prev + (guard_ms * factor + self.jitter_ms) / 1000.0
                self._life(ctx, node, prev, now - prev, guard_ms, factor, now=now, due=due)

    @staticmethod
    def _moved(ctx: Context, node: int, index: int, prev: float, t: float) -> bool:
        changes = ctx.config.changes(node, index, index)
        return bool(changes.size) and bool(crossing(changes, np.array([prev]), np.array([t]))[0])

    def finish(self, ctx: Context) -> None:
        for node, sent in self.pending.items() if ctx.timed else ():
            if ctx.t_end is not None and ctx.t_end - sent > self.timeout:
                self._no_reply(ctx, node, sent)

    def _no_reply(self, ctx: Context, node: int, sent: float, row: int = 0) -> None:
        self.emit(
            sent,
            node,
            0x700 + node,
            f"no reply to the guard request at {ctx.rel(sent)}",
            "no reply",
            "reply",
            row=row,
        )
