"""Finding: one rule violation at one time, written for a person as well as a parser."""

from __future__ import annotations

from dataclasses import dataclass

SEVERITIES = ("error", "warning", "info")


@dataclass
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

    @property
    def fails(self) -> bool:
        """Info findings are reported but do not fail a check run."""
        return self.severity != "info"

    def record(self) -> dict:
        """The JSONL / --json record (field names are a stable API)."""
        return {
            "kind": "finding",
            "t": self.t,
            "rule": self.rule,
            "severity": self.severity,
            "node": self.node,
            "cob_id": self.cob_id,
            "message": self.message,
            "measured": self.measured,
            "expected": self.expected,
            "why": self.why,
        }
