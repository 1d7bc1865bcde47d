"""PDOs from nodes that are not operational (CiA 301: PDOs only in OPERATIONAL)."""

from __future__ import annotations

import numpy as np

from ..protocol.services import Service
from .nmt_state import OPERATIONAL, state_name
from .rule import Context, Rule


class PdoStateRule(Rule):
    name = "pdo_not_operational"
    why = (
        "A node sending PDOs while not operational ignores NMT or reports a wrong state; consumers "
        "may act on data the master did not enable; check the node's NMT handling."
    )

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        g = ctx.gaps("pdo")
        if g.key.size == 0:
            return
        for cob, sl in g.groups():
            rows = g.row[sl]
            if b.service[rows[0]] != Service.TPDO:
                continue
            node = int(b.node[rows[0]])
            if node < 0 or node not in ctx.nmt.times:
                continue
            self.subjects.add(node)
            state = ctx.nmt.state_at(node, g.t[sl])
            bad = np.flatnonzero((state >= 0) & (state != OPERATIONAL))
            for i in self.capped(bad, g.t[sl][bad], node, cob).tolist():
                self.emit(
                    g.t[sl][i],
                    node,
                    cob,
                    f"PDO while node is {state_name(int(state[i]))}",
                    state_name(int(state[i])),
                    "operational",
                    row=rows[i],
                )
