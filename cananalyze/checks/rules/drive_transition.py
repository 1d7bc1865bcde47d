"""CiA 402: a state change the drive state machine does not allow, judged on two kinds
of evidence.

The statuswords: where every state the drive passes through would have been seen (its
statusword in an event-driven TPDO, transmission type 254/255, as the configuration in
force says: the log's writes, the network file, the DCF, without an inhibit time), a
change that is not a transition is one. A polled statusword (SDO) or a synchronous TPDO
samples the state, so two allowed transitions between samples look like one that is
not; those are not judged by the statuswords alone. A jump into fault (transitions 13
and 14 with a short fault reaction between) is allowed.

The commands: once the node's controlwords are on the bus (one seen before the state it
leaves), a drive that enables itself, reaching ready to switch on, switched on or
operation enabled from a lower state, must have had the commands that lead there: the
one in force and those sent since, applied in any order and as often as needed (a
sampled statusword may skip states), starting from the state it left. A drive whose
commands are not on the bus, or not decoded, is not judged this way.
"""

from __future__ import annotations

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.drive_tracker import COMMAND, RESET, STATE, DriveChange
from cananalyze.devices import cia402

# the states a drive enters only on a command, by how far up the enable sequence they are
_RANK = {
    cia402.SWITCH_ON_DISABLED: 1,
    cia402.READY: 2,
    cia402.SWITCHED_ON: 3,
    cia402.OPERATION_ENABLED: 4,
}
# the command table, plus what CiA 402 adds: enable operation in ready to switch on does
# transitions 3 and 4; and the transitions a drive makes by itself (1, 12, 14)
_LEADS = dict(cia402.COMMAND_TARGET)
_LEADS[(cia402.ENABLE_OPERATION, cia402.READY)] = cia402.SWITCHED_ON
_AUTO = {
    cia402.NOT_READY: cia402.SWITCH_ON_DISABLED,
    cia402.QUICK_STOP: cia402.SWITCH_ON_DISABLED,
    cia402.FAULT_REACTION: cia402.FAULT,
}


def _reachable(start: int, commands: set[int]) -> set[int]:
    """The states `commands` (each as often as needed) and the automatic transitions
    lead to from `start`."""
    seen, todo = {start}, [start]
    while todo:
        s = todo.pop()
        nexts = [_LEADS.get((c, s)) for c in commands] + [_AUTO.get(s)]
        for n in nexts:
            if n is not None and n not in seen:
                seen.add(n)
                todo.append(n)
    return seen


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
        self.in_force: dict[int, DriveChange] = {}  # node -> the last command seen
        # node -> (the command in force when the drive entered its state, those since)
        self.evidence: dict[int, tuple[DriveChange | None, list[DriveChange]]] = {}

    def _uncommanded(self, ctx: Context, c, before: int, force, since: list) -> bool:
        """A finding when the drive enabled itself past what its commands lead to; True
        when one was emitted."""
        up = _RANK.get(c.code, 0) > _RANK.get(before, 0) or (
            before not in _RANK and c.code in _RANK
        )
        if force is None or c.code not in _RANK or c.code == cia402.SWITCH_ON_DISABLED or not up:
            return False  # no command of this node seen before the state it left: no evidence
        commands = {force.code, *(x.code for x in since)}
        if c.code in _reachable(before, commands):
            return False
        shown = ", ".join(
            f"{cia402.COMMAND_NAMES[x.code]} (0x{x.word:04X}) at {ctx.rel(x.t)}" for x in since[:5]
        )
        more = f" and {len(since) - 5} more" if len(since) > 5 else ""
        self.emit(
            c.t,
            c.node,
            c.cob_id or None,
            f"drive went from {cia402.STATE_NAMES[before]} to {cia402.STATE_NAMES[c.code]} "
            f"(statusword 0x{c.word:04X} in {c.source.upper()}) without a command that leads "
            f"there: in force {cia402.COMMAND_NAMES[force.code]} (controlword "
            f"0x{force.word:04X} at {ctx.rel(force.t)} in {force.source.upper()}), "
            f"sent since: {shown + more or 'none'}",
            cia402.STATE_NAMES[c.code],
            "a state the commands on the bus lead to",
            row=c.row,
            basis="the node's controlwords on the bus since the state it left",
            why="A CiA 402 drive enters ready to switch on, switched on and operation "
            "enabled only on the master's commands (shutdown, switch on, enable operation); "
            "one that gets there with none that leads there moves on its own: check its "
            "firmware, a second master, or a command path the log does not show.",
        )
        return True

    def _every_state_seen(self, ctx: Context, change) -> bool:
        if not change.source.startswith("tpdo") or not change.cob_id:
            return False
        shows = getattr(ctx.config, "tpdo_shows_every_change", None)
        return bool(shows and shows(change.node, int(change.source[4:]), change.t))

    def process(self, ctx: Context) -> None:
        for c in ctx.batch.drive:
            if c.kind == RESET:
                self.last.pop(c.node, None)
                self.in_force.pop(c.node, None)
                self.evidence.pop(c.node, None)
                continue
            if c.kind == COMMAND:
                self.in_force[c.node] = c
                held = self.evidence.get(c.node)
                if held is not None:
                    held[1].append(c)
                continue
            if c.kind != STATE:
                continue
            before = self.last.get(c.node)
            self.last[c.node] = c.code
            force, since = self.evidence.get(c.node, (None, []))
            self.evidence[c.node] = (self.in_force.get(c.node), [])
            if before is None or cia402.UNKNOWN_STATE in (before, c.code):
                continue
            self.subjects.add(c.node)
            if self._uncommanded(ctx, c, before, force, since):
                continue
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
