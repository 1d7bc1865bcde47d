"""PDO length against its mapping: shorter than mapped is an error, longer a warning."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.checks.spans import pdo_stretches


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
            if bad.size == 0:
                continue
            got = d[bad].tolist()  # per frame: as columns
            name = f"{pdo.direction[0].upper()}PDO{pdo.number}"
            self.emit_many(
                g.t[idx[bad]],
                node,
                cob,
                lambda k, got=got, name=name, want=want: [
                    f"{name} has {got[j]} bytes, mapping needs {want}" for j in k.tolist()
                ],
                got,
                want,
                row=rows[bad],
                severity=[self.severity if x < want else "warning" for x in got],
            )
