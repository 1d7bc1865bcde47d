"""EMCY: each error raised and cleared, inhibit time 0x1015, errors still active at the end.

EMCY frames are rare, so this walks them one by one and keeps the active set per node.
"""

from __future__ import annotations

import numpy as np

from ..protocol.services import Service
from ..protocol.tables import emcy_class
from .rule import Context, Rule, ms


class EmcyRule(Rule):
    name = "emcy"
    severity = "warning"
    why = (
        "The node reported an error condition; read the error code and register, and the "
        "device manual's meaning of the manufacturer bytes."
    )

    def __init__(self, allow: list[int] | None = None, **kw) -> None:
        super().__init__(**kw)
        self.allow = {int(c) for c in allow or []}
        self.active: dict[int, dict[int, float]] = {}
        self.last_t: dict[int, float] = {}

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        rows = np.flatnonzero(b.service == Service.EMCY)
        if rows.size == 0:
            return
        fb = b.frames
        # columns as Python lists once: element access on numpy arrays costs more than the rule
        nodes = b.node[rows].tolist()
        times = fb.t[rows].tolist()
        dlcs = fb.dlc[rows].tolist()
        head = fb.data[rows, :3].tolist()
        inhibits: dict[int, int] = {}  # 0x1015 per node, read once per batch like the other rules
        for k, row in enumerate(rows.tolist()):
            node, t, dlc = nodes[k], times[k], dlcs[k]
            self.subjects.add(node)
            prev = self.last_t.get(node)
            self.last_t[node] = t
            inhibit = inhibits.get(node)
            if inhibit is None:
                inhibit = inhibits[node] = ctx.config.emcy_inhibit_100us(node, t) or 0
            if (
                prev is not None
                and inhibit
                and t - prev < inhibit * 1e-4 * (1 - self.tolerance)
                and not self.dropped(t, node, 0x80 + node)
            ):
                self.emit(
                    t,
                    node,
                    0x80 + node,
                    f"EMCY {ms(t - prev)} ms after the previous one, inhibit "
                    f"time 0x1015 is {inhibit * 0.1:g} ms",
                    ms(t - prev),
                    inhibit * 0.1,
                    row=row,
                    severity="error",
                    why="EMCY faster than its inhibit time can flood the bus in a fault storm; check 0x1015.",
                )
            if dlc < 8:
                if not self.dropped(t, node, 0x80 + node):
                    self.emit(
                        t,
                        node,
                        0x80 + node,
                        f"EMCY with {dlc} data bytes, CiA 301 needs 8",
                        dlc,
                        8,
                        row=row,
                        severity="error",
                        why="A short EMCY cannot be decoded by a standard master; check the node's firmware.",
                    )
                if dlc < 3:
                    continue
            b0, b1, reg = head[k]
            code = b0 | b1 << 8
            act = self.active.setdefault(node, {})
            if code == 0:
                if reg == 0:
                    act.clear()
                continue
            act[code] = t
            if code in self.allow or self.dropped(t, node, 0x80 + node):
                continue
            self.emit(
                t,
                node,
                0x80 + node,
                f"EMCY 0x{code:04X} ({emcy_class(code)}), error register 0x{reg:02X}",
                f"0x{code:04X}",
                "no EMCY"
                if not self.allow
                else "one of " + ", ".join(f"0x{c:04X}" for c in sorted(self.allow)),
                row=row,
            )

    def finish(self, ctx: Context) -> None:
        for node, act in sorted(self.active.items()):
            for code, t in sorted(act.items()):
                if code in self.allow or self.dropped(t, node, 0x80 + node):
                    continue
                self.emit(
                    t,
                    node,
                    0x80 + node,
                    f"EMCY 0x{code:04X} ({emcy_class(code)}) raised at {ctx.rel(t)} "
                    "still active at the end of the log",
                    f"0x{code:04X}",
                    "cleared",
                    why="No error reset (EMCY 0x0000) followed; the node may still be in its fault "
                    "reaction; check whether the cause was removed.",
                )

    def active_errors(self) -> dict[int, list[int]]:
        return {n: sorted(a) for n, a in self.active.items() if a}
