"""A node whose boot stopped: CiA 302-2's boot-up of a slave, step by step (decode/boot).

Judged once, at the end of the log (a boot may take seconds of SDO traffic): each life
of a node that did not become operational, at the step it stopped and with the boot
error status that step corresponds to. A node the master started anyway is no finding
(its story keeps what went wrong); a boot-up that no NMT start follows is told as info.
"""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.boot import BootFollower, declared_identity


class BootRule(Rule):
    name = "boot"
    timing = False  # judged by order: kept on logs without timestamps
    why = (
        "A node that does not finish its boot stays pre-operational: its PDOs never come; the "
        "step and the CiA 302-2 error status say what the master stopped at (identity, "
        "configuration, program download, error control, NMT start)."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.follower = BootFollower()

    def process(self, ctx: Context) -> None:
        self.follower.add(ctx.batch)

    def finish(self, ctx: Context) -> None:
        model = getattr(ctx.config, "model", None)
        stories = self.follower.stories(
            lambda n: declared_identity(model, n),
            ctx.config.heartbeat_ms if ctx.timed else None,
            ctx.t_end,
            timed=bool(ctx.timed),
        )
        for s in stories:
            if s.result != "stopped":
                continue
            self.subjects.add(s.node)
            t = s.steps[-1][0] if s.steps else s.t_boot
            if s.status:
                self.emit(
                    t,
                    s.node,
                    None,
                    f"boot of node {s.node} {s.verdict}",
                    s.stopped_at,
                    "operational",
                    why=None,
                )
            else:
                self.emit(
                    t,
                    s.node,
                    None,
                    f"boot of node {s.node}: {s.verdict}",
                    s.stopped_at,
                    "operational",
                    severity="info",
                )
