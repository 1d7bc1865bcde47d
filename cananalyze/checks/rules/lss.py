"""LSS sequences that failed: a configuration the slave refused or nobody answered, a
selective switch no slave answered, a fastscan that stopped half way.

A fastscan that finds no non-configured slave is no fault (every network with its
node-IDs set answers so), nor are the probes a scan leaves unanswered: only a scan that
found a slave and then lost it is.
"""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.lss import LssEvent, LssFollower, identity_text

LSS_MASTER_COB = 0x7E5


class LssRule(Rule):
    name = "lss"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "A node-ID or bit rate the LSS master could not set leaves the device unconfigured (it "
        "stays silent or takes the wrong ID); check that exactly one slave is in configuration "
        "state and that the value is one the device supports (CiA 305)."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.follower = LssFollower()

    def process(self, ctx: Context) -> None:
        self._judge(self.follower.add(ctx.batch), ctx)

    def finish(self, ctx: Context) -> None:
        self._judge(self.follower.finish(), ctx)

    def _judge(self, events: list[LssEvent], ctx: Context) -> None:
        for ev in events:
            self.subjects.add(None)
            who = identity_text(ev.identity)
            on = f" (selected: {who})" if who else ""
            if ev.step.startswith(("configure", "store")) and ev.result != "ok":
                severity = "warning" if ev.result == "no answer" else None
                what = f" node-ID {ev.node_id}" if ev.node_id is not None else ""
                self.emit(
                    ev.t,
                    None,
                    LSS_MASTER_COB,
                    f"LSS {ev.step}{what}: {ev.result}{on}",
                    ev.result,
                    "ok",
                    row=ev.row,
                    severity=severity,
                )
            elif ev.step == "switch state selective" and ev.result == "no answer":
                self.emit(
                    ev.t,
                    None,
                    LSS_MASTER_COB,
                    f"LSS switch state selective: no slave answered ({who})",
                    "no answer",
                    "selected",
                    row=ev.row,
                    severity="warning",
                )
            elif ev.step == "fastscan" and ev.result.startswith("incomplete"):
                self.emit(
                    ev.t,
                    None,
                    LSS_MASTER_COB,
                    f"LSS fastscan {ev.result}{on}",
                    ev.result,
                    "found",
                    row=ev.row,
                    severity="warning",
                )
