"""Finding: one rule violation at one time, written for a person as well as a parser."""

from __future__ import annotations

from dataclasses import dataclass

SEVERITIES = ("error", "warning", "info")


@dataclass(slots=True)  # a misconfigured log can hold many: no per-object dict
class Finding:
    t: float
    rule: str
    severity: str
    node: int | None
    cob_id: int | None
    message: str
    measured: object = None
    expected: object = None
    why: str = ""
    row: int = 0  # row of the batch the finding belongs to (for JSONL placement)
    t_rel: float | None = None  # seconds since the first frame of the log (set by the Checker)
    # where the expected value came from ("0x1017 written at +12.300 s", "network file",
    # "EDS default", "learned from the log's median over +0.000..+12.300 s")
    basis: str = ""
    line: int | None = None  # the frame's line, in a log without timestamps
    # an end-of-log result (errors still active, a node that stopped): the terminal never
    # hides it. Not every finding `finish` makes: a gap judged there against a learned
    # period is an ordinary finding, capped like the others.
    at_end: bool = False
    # the bus (channel name) of a log with several: node 5 on can1 is not node 5 on can0;
    # None on a log of one bus (whose outputs do not name it)
    bus: str | None = None

    def __post_init__(self) -> None:
        self.measured = tidy(self.measured)
        self.expected = tidy(self.expected)

    @property
    def fails(self) -> bool:
        """Info findings are reported but do not fail a check run."""
        return self.severity != "info"

    def record(self) -> dict:
        """The JSONL / --json record (field names are a stable API; `bus` only on a log
        of several buses)."""
        rec = {
            "kind": "finding",
            "t": self.t,
            "t_rel": None if self.t_rel is None else round(self.t_rel, 6),
            "rule": self.rule,
            "severity": self.severity,
            "node": self.node,
            "cob_id": self.cob_id,
            "message": self.message,
            "measured": self.measured,
            "expected": self.expected,
            "why": self.why,
            "basis": self.basis,
            "line": self.line,
        }
        if self.bus is not None:
            rec["bus"] = self.bus
        return rec

    @property
    def where(self) -> str:
        """Which node, as a person reads it: 'node 5', or 'can1 node 5' on several buses."""
        who = "node -" if self.node is None else f"node {self.node}"
        return who if self.bus is None else f"{self.bus} {who}"


# the findings table's columns (export, load().findings, a fleet's part): the record's
# fields after "kind", in its order
TABLE_COLUMNS = ("t", "t_rel", "rule", "severity", "node", "cob_id", "message")
TABLE_COLUMNS += ("measured", "expected", "why", "basis", "line")


def tidy(value: object) -> object:
    """Floats rounded to 12 significant digits: 3276.7, not 3276.7000000000003 (float noise
    from scaling), in the printed line and in JSON alike. Lists are tidied item by item."""
    if isinstance(value, float):
        return float(f"{value:.12g}")
    if isinstance(value, (list, tuple)):
        return [tidy(v) for v in value]
    return value


def show(value: object) -> str:
    """A measured/expected value as a person reads it: 100 not 100.0, ranges as lo..hi."""
    if isinstance(value, float):
        return f"{value:.12g}"
    if isinstance(value, (list, tuple)) and len(value) == 2:
        return f"{show(value[0])}..{show(value[1])}"
    if value is None:
        return "none"
    return str(value)


def rel_time(t: float, t0: float | None) -> str:
    """Time since the first frame, as engineers read a log: '+4.407 s'."""
    return f"+{t - (t0 if t0 is not None else 0.0):.3f} s"
