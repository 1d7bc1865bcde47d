"""CiA 402: a command the drive did not follow within `timeout_ms`.

A new controlword command that asks the state in force for a transition (shutdown in
switch on disabled, enable operation in switched on, ...) expects its target state. It
is judged only on evidence: a statusword seen later than the deadline while the drive
is still not there (a drive nobody reads is not judged). A later command, a fault or a
reset replaces the expectation.
"""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.decode.drive_tracker import COMMAND, RESET, SEEN, STATE
from cananalyze.devices import cia402


class DriveCommandRule(Rule):
    name = "drive_command"
    severity = "error"
    why = (
        "The drive did not reach the state its command asks for: check the statusword's "
        "flags (voltage enabled, warning, internal limit), the option codes 0x605A-0x605E "
        "and whether the master sent the whole enable sequence."
    )

    def __init__(self, timeout_ms: float = 1000.0, **kw) -> None:
        super().__init__(**kw)
        self.timeout = float(timeout_ms) / 1000.0
        self.state: dict[int, int] = {}
        self.pending: dict[int, tuple] = {}  # node -> (t, command, target, change)

    def process(self, ctx: Context) -> None:
        for c in ctx.batch.drive:
            node = c.node
            if c.kind == RESET:
                self.state.pop(node, None)
                self.pending.pop(node, None)
            elif c.kind == COMMAND:
                state = self.state.get(node)
                target = cia402.COMMAND_TARGET.get((c.code, state)) if state is not None else None
                if target is None:
                    self.pending.pop(node, None)
                else:
                    self.pending[node] = (c.t, c.code, target, c)
                    self.subjects.add(node)
            elif c.kind in (STATE, SEEN):
                held = self.state.get(node)  # the state in force up to this row
                if c.kind == STATE:
                    self.state[node] = c.code
                p = self.pending.get(node)
                if p is None:
                    continue
                t0, command, target, cmd = p
                deadline = t0 + self.timeout
                if c.t > deadline and held != target:
                    self.pending.pop(node)
                    late = (
                        f"; reached {ms(c.t - t0)} ms after it"
                        if c.kind == STATE and c.code == target
                        else f"; {cia402.STATE_NAMES[held]} until {ctx.rel(c.t)}"
                        if held is not None and c.kind == STATE
                        else f"; still {cia402.STATE_NAMES[held]} at {ctx.rel(c.t)}"
                        if held is not None
                        else ""
                    )
                    self.emit(
                        deadline,
                        node,
                        cmd.cob_id or None,
                        f"drive not {cia402.STATE_NAMES[target]} {ms(self.timeout)} ms after "
                        f"{cia402.COMMAND_NAMES[command]} (controlword 0x{cmd.word:04X} at "
                        f"{ctx.rel(t0)}){late}",
                        cia402.STATE_NAMES[held] if held is not None else None,
                        cia402.STATE_NAMES[target],
                        row=c.row,
                    )
                elif c.code == target or c.code in (cia402.FAULT_REACTION, cia402.FAULT):
                    self.pending.pop(node)
