"""PDO frames on a COB-ID whose PDO is configured as not valid (bit 31 of 0x14xx/0x18xx:1).

The network model knows which PDOs are switched off (device profile/DCF, network
file, SDO writes in the log) and the PDO decoder marks such rows with a
`pdo_problem` row note; this rule turns those marks into one finding per COB-ID.
"""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.model import NOT_VALID


class PdoValidRule(Rule):
    name = "pdo_not_valid"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "A node ignores a PDO whose COB-ID is marked not valid: an RPDO sent there never "
        "reaches the application, a TPDO there contradicts the configuration; enable the PDO "
        "(clear bit 31 of its COB-ID by SDO) or stop sending it."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.seen: dict[int, list] = {}  # COB-ID -> [first t, node, count, problem, row]

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        for rows, note in b.row_notes:
            problem = note.get("pdo_problem")
            if not problem or NOT_VALID not in problem or len(rows) == 0:
                continue
            first = int(rows[0])
            cob = int(b.frames.can_id[first])
            node = int(b.node[first])
            entry = self.seen.get(cob)
            if entry is None:
                self.seen[cob] = [float(ctx.t[first]), node if node >= 0 else None, 0, problem]
                entry = self.seen[cob]
            entry[2] += len(rows)
            if entry[1] is not None:
                self.subjects.add(entry[1])

    def finish(self, ctx: Context) -> None:
        for cob, (t, node, count, problem) in sorted(self.seen.items()):
            self.emit(
                t,
                node,
                cob,
                f"{count} frame(s) on 0x{cob:03X} from {ctx.rel(t)} on: {problem}",
                count,
                0,
            )
