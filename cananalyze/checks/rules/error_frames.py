"""CAN error frames: at most `max` (default 0) in the log."""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule
from cananalyze.protocol.services import Service


class ErrorFrameRule(Rule):
    name = "error_frames"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "Error frames come from wiring, termination, bit-timing or a failing transceiver; each one "
        "destroys a frame and repeated ones drive nodes bus-off; check termination and bitrate."
    )

    def __init__(self, max: int = 0, **kw) -> None:  # noqa: A002 - the rules file's key
        super().__init__(**kw)
        self.max = int(max)
        self.count = 0
        self.first: float | None = None

    def process(self, ctx: Context) -> None:
        rows = ctx.rows(Service.ERROR_FRAME)
        self.subjects.add(None)
        if rows.size:
            if self.first is None:
                self.first = float(ctx.t[rows[0]])
            self.count += int(rows.size)

    def finish(self, ctx: Context) -> None:
        if self.count > self.max:
            self.emit(
                self.first or 0.0,
                None,
                None,
                f"{self.count} CAN error frames, at most {self.max} allowed",
                self.count,
                self.max,
            )
