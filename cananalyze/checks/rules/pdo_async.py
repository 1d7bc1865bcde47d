"""Asynchronous TPDOs (type 254/255): inhibit time (100 us units) and event timer while operational.

Each gap is judged by the PDO parameters in force at its frame (one lookup per stretch).
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.checks.spans import pdo_stretches
from cananalyze.protocol.nmt import OPERATIONAL

# CiA 301 lets a node send PDOs only while operational: a node whose NMT state the log
# never showed (no boot-up, heartbeat or NMT command seen) but whose PDOs bound a gap was
# operational at both ends; a stop or reset in between would have made its state known.
_SENDING = (OPERATIONAL, -1)


class PdoAsyncRule(Rule):
    name = "pdo_async"
    why = (
        "An inhibit time violation floods the bus; an event-timer overrun means consumers see stale "
        "values or time out; check 0x18xx:3 and 0x18xx:5 and the node's cycle time."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.last: dict[int, tuple[float, int, int]] = {}  # COB-ID -> (t, node, event timer)
        self.reported: set[tuple[int, float]] = set()  # (COB-ID, t) silences tick() saw

    @staticmethod
    def _origin(ctx: Context, node: int, cob: int, t: float, sub: int) -> str:
        """Where a TPDO's inhibit time (sub 3) or event timer (sub 5) came from."""
        cfg = ctx.config.pdo_params(cob, t)
        number = cfg[1].number if cfg is not None else 1
        return ctx.config.origin(node, 0x1800 + number - 1, sub, t, ctx.t0)

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("pdo")
        if g.key.size == 0:
            return
        gap = g.gap
        for cob, (node, pdo), idx, judged in pdo_stretches(ctx, g):
            if pdo.direction != "tx" or pdo.transmission_type < 254:
                continue
            self.subjects.add(node)
            if idx.size:
                self.last[cob] = (float(g.t[idx[-1]]), node, int(pdo.event_timer))
            idx = idx[judged]
            gg = gap[idx]
            if pdo.inhibit_time:
                inhibit = pdo.inhibit_time * 1e-4
                bad = idx[gg < inhibit * (1 - self.tolerance)]
                if bad.size:  # per frame: as columns (emit_many applies the cap)
                    gaps_ms = [ms(x) for x in gap[bad].tolist()]
                    inh_ms = pdo.inhibit_time * 0.1
                    self.emit_many(
                        g.t[bad],
                        node,
                        cob,
                        lambda k, gaps_ms=gaps_ms, inh_ms=inh_ms: [
                            f"{gaps_ms[j]} ms after the previous one, inhibit time {inh_ms:g} ms"
                            for j in k.tolist()
                        ],
                        gaps_ms,
                        inh_ms,
                        row=g.row[bad],
                        basis=[self._origin(ctx, node, cob, x, 3) for x in g.t[bad].tolist()],
                    )
            if pdo.event_timer:
                limit = self.late(pdo.event_timer) / 1000.0
                cand = self.capped(idx[gg > limit], g.prev[idx[gg > limit]], node, cob)
                if cand.size:
                    before = ctx.nmt.state_at(node, g.prev[cand])
                    after = ctx.nmt.state_at(node, g.t[cand])
                    for j, i in enumerate(cand.tolist()):
                        if (cob, float(g.prev[i])) in self.reported:
                            continue
                        if before[j] in _SENDING and after[j] in _SENDING:
                            self.emit(
                                g.prev[i],
                                node,
                                cob,
                                f"no PDO for {ms(gap[i])} ms while operational, "
                                f"event timer {pdo.event_timer} ms",
                                ms(gap[i]),
                                pdo.event_timer,
                                row=g.row[i],
                                basis=self._origin(ctx, node, cob, float(g.prev[i]), 5),
                            )

    def tick(self, ctx: Context, now: float) -> None:
        """Live: an event-timer PDO overdue while its node is operational, reported once."""
        for cob, (last, node, timer) in sorted(self.last.items()):
            if not timer or (cob, last) in self.reported:
                continue
            if (now - last) * 1000 <= self.late(timer):
                continue
            state = ctx.nmt.state_at(node, np.array([last, now]))
            if not np.isin(state, _SENDING).all():
                continue
            self.reported.add((cob, last))
            self.emit(
                now,
                node,
                cob,
                f"no PDO since {ctx.rel(last)} ({ms(now - last)} ms so far) while operational, "
                f"event timer {timer} ms" + self.quiet(ctx, last + self.late(timer) / 1000.0),
                ms(now - last),
                timer,
                basis=self._origin(ctx, node, cob, last, 5),
            )
