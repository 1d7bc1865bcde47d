"""PDO length against its mapping: shorter than mapped is an error, longer a warning."""

from __future__ import annotations

import numpy as np

from ..rule import Context, Rule
from ..spans import pdo_stretches


class PdoLengthRule(Rule):
    name = "pdo_length"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "A PDO shorter than its mapping cannot be applied (the receiver should raise EMCY 0x8210); "
        "one longer than mapped hints at a mapping mismatch between producer and consumer; compare "
        "both nodes' 0x1600/0x1A00 mappings."
    )

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("pdo")
        if g.key.size == 0:
            return
        dlc = ctx.batch.frames.dlc
        for cob, (node, pdo), idx, _ in pdo_stretches(ctx, g):
            want = pdo.expected_bytes
            if want is None:
                continue
            self.subjects.add(node)
            rows = g.row[idx]
            d = dlc[rows]
            bad = np.flatnonzero(d != want)
            for i in self.capped(bad, g.t[idx][bad], node, cob).tolist():
                short = d[i] < want
                self.emit(
                    g.t[idx[i]],
                    node,
                    cob,
                    f"{pdo.direction[0].upper()}PDO{pdo.number} has {int(d[i])} bytes, mapping needs {want}",
                    int(d[i]),
                    want,
                    row=rows[i],
                    severity=None if short else "warning",
                )
