"""CiA 402: a state change the drive state machine does not allow.

Judged only where every state the drive passes through would have been seen: its
statusword in an event-driven TPDO (transmission type 254/255, as the configuration in
force says: the log's writes, the network file, the DCF) without an inhibit time. A
polled statusword (SDO) or a synchronous TPDO samples the state, so two allowed
transitions between samples look like one that is not; those are not judged. A jump
into fault (transitions 13 and 14 with a short fault reaction between) is allowed.
"""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.drive_tracker import RESET, STATE
from cananalyze.devices import cia402


class DriveTransitionRule(Rule):
    name = "drive_transition"
    severity = "error"
    timing = False  # judged by the order of the statuswords: kept on logs without times
    why = (
        "CiA 402 allows only the transitions of its state machine; a drive that jumps "
        "elsewhere has a firmware or master problem. Compare with the controlwords sent "
        "just before."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.last: dict[int, int] = {}

    def _every_state_seen(self, ctx: Context, change) -> bool:
        if not change.source.startswith("tpdo") or not change.cob_id:
            return False
        shows = getattr(ctx.config, "tpdo_shows_every_change", None)
        return bool(shows and shows(change.node, int(change.source[4:]), change.t))

    def process(self, ctx: Context) -> None:
        for c in ctx.batch.drive:
            if c.kind == RESET:
                self.last.pop(c.node, None)
                continue
            if c.kind != STATE:
                continue
            before = self.last.get(c.node)
            self.last[c.node] = c.code
            if before is None or cia402.UNKNOWN_STATE in (before, c.code):
                continue
            self.subjects.add(c.node)
            if (before, c.code) in cia402.TRANSITIONS:
                continue
            if c.code == cia402.FAULT:  # 13 then 14, the fault reaction too short to see
                continue
            if not self._every_state_seen(ctx, c):
                continue
            self.emit(
                c.t,
                c.node,
                c.cob_id,
                f"drive went from {cia402.STATE_NAMES[before]} to "
                f"{cia402.STATE_NAMES[c.code]} (statusword 0x{c.word:04X} in {c.source.upper()}), "
                "a transition CiA 402 does not have",
                cia402.STATE_NAMES[c.code],
                "a CiA 402 transition",
                row=c.row,
            )
