"""PDOs from nodes that are not operational (CiA 301: PDOs only in OPERATIONAL)."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.protocol.nmt import OPERATIONAL, state_name
from cananalyze.protocol.services import Service


class PdoStateRule(Rule):
    name = "pdo_not_operational"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "A node sending PDOs while not operational ignores NMT or reports a wrong state; consumers "
        "may act on data the master did not enable; check the node's NMT handling."
    )

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        g = ctx.gaps("pdo")
        if g.key.size == 0:
            return
        # NMT state of every PDO row, one lookup per node (not per COB-ID)
        node_of = b.node[g.row]
        present = np.bincount(node_of.astype(np.intp) + 1) if node_of.size else np.zeros(0)
        # a node whose state holds over the batch (the usual case): one value for its rows
        steady = np.full(present.size, -1, np.int16)  # by node + 1
        varying = []
        t_lo, t_hi = (float(g.t.min()), float(g.t.max())) if g.t.size else (0.0, 0.0)
        for node in (np.flatnonzero(present) - 1).tolist():  # nodes -1..127, ascending
            if node >= 0 and node in ctx.nmt.times:
                s = ctx.nmt.steady_state(node, t_lo, t_hi)
                if s is None:
                    varying.append(node)
                else:
                    steady[node + 1] = s
        starts = g.starts
        heads = g.row[starts]
        if varying or bool(((steady >= 0) & (steady != OPERATIONAL)).any()):
            state = steady[node_of.astype(np.intp) + 1]
            for node in varying:
                at = np.flatnonzero(node_of == node)
                state[at] = ctx.nmt.state_at(node, g.t[at])
            bad_all = (state >= 0) & (state != OPERATIONAL)
            any_bad = np.add.reduceat(bad_all, starts) > 0 if starts.size else np.zeros(0, bool)
        else:  # every node operational (or unknown) all batch long: no row to look at
            any_bad = np.zeros(starts.size, bool)
        for (cob, sl), svc, node, has_bad in zip(
            g.groups(),
            b.service[heads].tolist(),
            b.node[heads].tolist(),
            any_bad.tolist(),
            strict=True,
        ):
            if svc != Service.TPDO:
                continue
            if node < 0 or node not in ctx.nmt.times:
                continue
            self.subjects.add(node)
            if not has_bad:
                continue
            rows = g.row[sl]
            st = state[sl]
            bad = np.flatnonzero(bad_all[sl])
            names = [state_name(s) for s in st[bad].tolist()]  # per frame: as columns
            self.emit_many(
                g.t[sl][bad],
                node,
                cob,
                lambda k, names=names: [f"PDO while node is {names[j]}" for j in k.tolist()],
                names,
                state_name(OPERATIONAL),
                row=rows[bad],
            )
