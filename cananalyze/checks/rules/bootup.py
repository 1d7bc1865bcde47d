"""Unexpected boot-ups: a node that was already alive boots again without an NMT reset."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.senders import SENT as _SENT
from cananalyze.decode.senders import senders as _senders
from cananalyze.protocol.nmt import ALL_NODES, RESET_COMMUNICATION, RESET_NODE
from cananalyze.protocol.services import Service


class BootupRule(Rule):
    name = "unexpected_bootup"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "A node that boots without being told to has reset itself (watchdog, brown-out, crash); "
        "it lost its configuration and is pre-operational; check its supply and EMCY history."
    )

    def __init__(self, reset_window_s: float = 10.0, **kw) -> None:
        super().__init__(**kw)
        self.window = float(reset_window_s)
        self.alive = np.zeros(128, bool)
        self.last_reset: dict[int, float] = {}

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        boots = ctx.rows(Service.BOOTUP)
        nmt = ctx.rows(Service.NMT)
        if boots.size == 0 and nmt.size == 0:
            self.alive[_senders(b)] = True
            return
        fb = b.frames
        events = sorted(
            [(int(r), "boot") for r in boots.tolist()] + [(int(r), "nmt") for r in nmt.tolist()]
        )
        sent_mask = _SENT[b.service] & (b.node >= 0)
        first_row = np.full(128, len(b), np.int64)
        rows = np.flatnonzero(sent_mask)
        first_row[b.node[rows][::-1]] = rows[::-1]  # last write wins: the first row per node
        for row, kind in events:
            if kind == "nmt":
                if fb.dlc[row] >= 2 and fb.data[row, 0] in (RESET_NODE, RESET_COMMUNICATION):
                    target = int(fb.data[row, 1])
                    for n in range(1, 128) if target == ALL_NODES else [target]:
                        self.last_reset[n] = float(fb.t[row])
                continue
            node = int(b.node[row])
            self.subjects.add(node)
            t = float(fb.t[row])
            seen_before = self.alive[node] or first_row[node] < row
            reset = self.last_reset.get(node)
            late = reset is None or (ctx.timed and t - reset > self.window)
            if seen_before and late:
                self.emit(
                    t,
                    node,
                    0x700 + node,
                    f"node {node} booted without an NMT reset command",
                    "boot-up",
                    "no boot-up while running",
                    row=row,
                )
            self.last_reset.pop(node, None)
        self.alive[b.node[rows]] = True
