"""Rule base and the per-batch context every rule reads.

A rule looks at columns (gaps per node or COB-ID, computed once per batch by the
context) and emits Findings; per-frame Python only for rare rows. Each rule keeps
the set of nodes it judged, so a JUnit report can show passing testcases too.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from cananalyze.checks.config import ConfigSource
from cananalyze.checks.gaps import Gaps, grouped_gaps
from cananalyze.core.finding import Finding, rel_time
from cananalyze.core.finding_columns import FindingColumns, Texts
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.nmt_state import NmtStates
from cananalyze.protocol.services import Service

# Which rows each shared gap table covers, and its key column.
_GAP_TABLES = {
    "heartbeat": ((Service.HEARTBEAT,), "node", 128),
    "pdo": ((Service.TPDO, Service.RPDO), "can_id", 2048),
    "sync": ((Service.SYNC,), None, 1),
}


# The bulk services, one range of codes (PDO, SDO and heartbeat: nine frames in ten);
# Context.rows looks for the others among the rows outside it
_BULK_FIRST, _BULK_LAST = Service.TPDO, Service.HEARTBEAT
assert [int(s) for s in Service if _BULK_FIRST <= s <= _BULK_LAST] == [
    Service.TPDO,
    Service.RPDO,
    Service.SDO_REQUEST,
    Service.SDO_RESPONSE,
    Service.HEARTBEAT,
]


def _any_of(svc: np.ndarray, services: tuple[Service, ...]) -> np.ndarray:
    """Mask of the rows of any of `services`."""
    if len(services) <= 3:  # a few comparisons beat np.isin's sort
        mask = svc == services[0]
        for s in services[1:]:
            mask |= svc == s
        return mask
    return np.isin(svc, np.array(services, np.uint8))


class GapState:
    """Carried last-frame times per gap table, owned by the Checker."""

    def __init__(self) -> None:
        self.last = {name: np.full(size, np.nan) for name, (_, _, size) in _GAP_TABLES.items()}


class Context:
    def __init__(
        self,
        batch: DecodedBatch,
        config: ConfigSource,
        nmt: NmtStates,
        state: GapState,
        t_end: float | None = None,
        t0: float | None = None,
        timed: bool = True,
    ) -> None:
        self.batch = batch
        # False: the log has no timestamps; `t` is then each frame's line (its order)
        self.timed = timed
        self.config = config
        self.nmt = nmt
        self.t = batch.frames.t
        self.t_first = float(self.t[0]) if len(batch) else (t_end or 0.0)
        self.t_end = t_end  # set only at finish: time of the last frame of the log
        self.t0 = t0 if t0 is not None else self.t_first  # first frame of the log
        self._state = state
        self._gaps: dict[str, Gaps] = {}
        self._rows: dict[tuple[Service, ...], np.ndarray] = {}
        self._rare_rows: tuple[np.ndarray, np.ndarray] | None = None
        # per-batch results several rules read (spans.pdo_stretches), computed by the first
        self.shared: dict[str, object] = {}
        # live tick: the bus's latest frame (a deadline past it is seen on the wall clock)
        self.t_bus: float | None = None

    def rel(self, t: float) -> str:
        """A time in a finding's message, from the start of the log ('+4.407 s'), or
        the line of a log without timestamps."""
        return rel_time(t, self.t0) if self.timed else f"line {int(t)}"

    def rows(self, *services: Service) -> np.ndarray:
        """The batch's rows of these services, ascending; asked once per batch (a dozen
        rules and the timing ask for the same few services). Read-only: shared."""
        got = self._rows.get(services)
        if got is None:
            got = self._rows[services] = self._find_rows(services)
            got.flags.writeable = False
        return got

    def _find_rows(self, services: tuple[Service, ...]) -> np.ndarray:
        svc = self.batch.service
        if svc.dtype == np.uint8 and not any(_BULK_FIRST <= s <= _BULK_LAST for s in services):
            # a rare service: looked for among the rows of the rare services only
            rare, rare_svc = self._rare()
            return rare[_any_of(rare_svc, services)]
        return np.flatnonzero(_any_of(svc, services))

    def _rare(self) -> tuple[np.ndarray, np.ndarray]:
        """Rows of every service but the bulk ones (PDO, SDO, heartbeat), a tenth of a
        batch found with one subtraction and one comparison, and their services."""
        if self._rare_rows is None:
            svc = self.batch.service
            bulk = np.subtract(svc, np.uint8(_BULK_FIRST), dtype=np.uint8)  # below: wraps past
            rows = np.flatnonzero(bulk > _BULK_LAST - _BULK_FIRST)
            self._rare_rows = (rows, svc[rows])
        return self._rare_rows

    def gaps(self, name: str) -> Gaps:
        g = self._gaps.get(name)
        if g is None:
            services, keycol, _ = _GAP_TABLES[name]
            rows = self.rows(*services)
            fb = self.batch.frames
            if keycol == "node":
                keys = self.batch.node[rows]
            elif keycol == "can_id":
                keys = fb.can_id[rows]
            else:
                keys = np.zeros(rows.size, np.intp)
            g = grouped_gaps(fb.t, keys, rows, self._state.last[name])
            self._gaps[name] = g
        return g


# The absolute floor of every timing tolerance, in ms: a stack's scheduler (an RTOS tick,
# a Linux thread) adds a few ms whatever the period, so 11.8 ms against a 10 ms event
# timer is jitter, not a fault. Overridable per rule and file-wide (`jitter_ms:`).
JITTER_MS = 2.0


class Rule:
    name = ""
    severity = "error"
    tolerance = 0.1
    jitter_ms = JITTER_MS
    why = ""
    # per rule and node/COB-ID: a bound on memory for a badly misconfigured log (the rest
    # are counted in one closing finding); the terminal shows fewer (FindingsSink)
    max_findings = 100_000
    timing = True  # False: judged by frame order alone (kept on logs without timestamps)
    needs_gaps: tuple[str, ...] = ()  # gap tables whose every gap Timing must keep (all_gaps)
    # several buses: an assertion whose subject another bus holds skips its `finish`
    # (`engine.whole_log`; such rules say where their subject is with `present(checker)`)
    elsewhere = False
    # the Checker's list of its rules with findings to take (each told once per take), so
    # a batch's findings are taken from those few, not asked of every rule: a rules file
    # may hold 50,000 assertions (issue 38). A rule belongs to the last Checker given it.
    _board: list[Rule] | None = None
    _told = False

    def __init__(
        self,
        severity: str | None = None,
        tolerance: float | None = None,
        jitter_ms: float | None = None,
        **params,
    ) -> None:
        if severity:
            self.severity = severity
        if tolerance is not None:
            self.tolerance = float(tolerance)
        if jitter_ms is not None:
            self.jitter_ms = float(jitter_ms)
        self.params = params
        self.subjects: set[int | None] = set()
        self.out: list[Finding] = []  # emitted one by one since the last block
        self._parts: list[FindingColumns] = []  # in emission order
        # set by the Checker at the end of the log: what is found then is an end-of-log
        # result (errors still active, silence) unless the rule says otherwise
        self.ending = False
        self._count: Counter = Counter()
        self._first_dropped: dict = {}

    def slack(self, period_ms: float) -> float:
        """How far past `period_ms` (ms) a frame may come: the relative tolerance, at least
        the absolute jitter floor."""
        return max(period_ms * self.tolerance, self.jitter_ms)

    def late(self, period_ms: float) -> float:
        """The longest gap (ms) still on time for a period."""
        return period_ms + self.slack(period_ms)

    def process(self, ctx: Context) -> None:
        """Check one batch; append to self.out. (A rule that does not override it is
        judged at the end only: the Checker does not call it per batch.)"""

    # A subclass may define `together(rules) -> processor(ctx)`, a classmethod: one
    # processor for all of a Checker's rules of that class, called per batch instead of
    # each rule's `process` (at the place of the first of them), which must judge each
    # rule as its `process` would (assert_heartbeat: a batch touches only the assertions
    # on the nodes it carries, and identical assertions share one comparison).
    together = None

    def tick(self, ctx: Context, now: float) -> None:
        """Live: the bus reached `now` (the latest frame's time); deadline rules report
        what is already overdue (once: the frame that ends the silence, or the end of
        the log, does not report it again)."""

    @staticmethod
    def quiet(ctx: Context, due: float) -> str:
        """Live: said in a tick's finding whose deadline `due` passed after the bus's latest
        frame, so on the wall clock alone: then the silence may be the adapter's."""
        if ctx.t_bus is None or due <= ctx.t_bus:
            return ""
        return (
            f"; no frame from any node since {ctx.rel(ctx.t_bus)} "
            "(the adapter or the logger may have stopped)"
        )

    def finish(self, ctx: Context) -> None:
        """End of log checks (ctx.t_end set, zero rows)."""

    def capped(
        self, idx: np.ndarray, times: np.ndarray, node: int | None, cob_id: int | None
    ) -> np.ndarray:
        """The first candidates this rule may still list for node/COB-ID; the rest only counted.

        Keeps a badly misconfigured log from costing one Python call per violating frame.
        """
        key = (node, cob_id)
        left = max(self.max_findings - self._count[key], 0)
        if idx.size > left:
            self._count[key] += idx.size - left
            self._first_dropped.setdefault(key, float(times[left]))
            return idx[:left]
        return idx

    def emit(
        self,
        t: float,
        node: int | None,
        cob_id: int | None,
        message: str,
        measured=None,
        expected=None,
        row: int = 0,
        why: str | None = None,
        severity: str | None = None,
        basis: str = "",
    ) -> None:
        """One finding (rare, stateful rules); one `finish` emits is an end-of-log result
        the terminal never hides (`at_end`)."""
        key = (node, cob_id)
        self._count[key] += 1
        if self._count[key] > self.max_findings:
            self._first_dropped.setdefault(key, t)
            return
        self.out.append(
            Finding(
                float(t),
                self.name,
                severity or self.severity,
                node,
                cob_id,
                message,
                measured,
                expected,
                why if why is not None else self.why,
                int(row),
                basis=basis,
                at_end=self.ending,
            )
        )
        self._tell()

    def emit_many(
        self,
        t: np.ndarray,
        node: int | None,
        cob_id: int | None,
        text: Texts,
        measured,
        expected,
        row=0,
        why: str | None = None,
        severity: str | None = None,
        basis="",
        at_end: bool | None = None,
    ) -> None:
        """Findings of one node/COB-ID as columns (per-frame violations): `text(idx)`
        builds the messages of rows `idx` only when an output reads them. The cap
        applies as for `emit`, in order."""
        n = int(np.size(t))
        if n == 0:
            return
        key = (node, cob_id)
        left = max(self.max_findings - self._count[key], 0)
        self._count[key] += n
        keep = None
        if n > left:
            self._first_dropped.setdefault(key, float(np.asarray(t)[left]))
            keep = np.arange(left)
            if left == 0:
                return
        block = FindingColumns.block(
            self.name,
            severity or self.severity,
            t,
            node,
            cob_id,
            text,
            measured,
            expected,
            why if why is not None else self.why,
            row,
            basis,
        )
        block.at_end[:] = self.ending if at_end is None else at_end
        self._flush()
        self._parts.append(block if keep is None else block.take(keep))
        self._tell()

    def emit_rows(self, block: FindingColumns) -> None:
        """Findings built as columns by the rule itself (`FindingColumns.block`), which
        has counted them against the cap (`_count`)."""
        block.at_end[:] = self.ending
        self._flush()
        self._parts.append(block)
        self._tell()

    def _tell(self) -> None:
        """Put this rule on its Checker's board of rules with findings to take."""
        if not self._told:
            self._told = True
            if self._board is not None:
                self._board.append(self)

    def _flush(self) -> None:
        if self.out:
            self._parts.append(FindingColumns.of(self.out))
            self.out = []

    def close(self, t_end: float) -> None:
        """One finding per node/COB-ID that had more than max_findings."""
        for (node, cob), n in self._count.items():
            if n > self.max_findings:
                extra = n - self.max_findings
                self.out.append(
                    Finding(
                        self._first_dropped[(node, cob)],
                        self.name,
                        self.severity,
                        node,
                        cob,
                        f"{extra} more like this not listed ({n} in all)",
                        n,
                        0,
                        self.why,
                        0,
                        at_end=True,
                    )
                )
                self._tell()

    def take(self) -> list[FindingColumns]:
        """What was found since the last take, in emission order."""
        return [p if isinstance(p, FindingColumns) else FindingColumns.of(p) for p in self.taken()]

    def taken(self) -> list[FindingColumns | list[Finding]]:
        """`take`, with the findings emitted one by one since the last block left a list
        of `Finding`s: the Checker makes one FindingColumns of many rules' lists (the
        same columns as one per rule; 50,000 assertions each telling a silent node)."""
        out, self._parts = self._parts, []
        if self.out:
            out.append(self.out)
            self.out = []
        self._told = False
        return out


def ms(seconds: float) -> float:
    return round(float(seconds) * 1000.0, 3)
