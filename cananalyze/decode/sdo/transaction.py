"""What the SDO tracker hands out: one record per transaction, one role per frame."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class FrameRole:
    """Where one SDO frame stands in its transfer (the stateful answer, block segments included)."""

    command: str
    text: str
    index: int | None = None
    subindex: int | None = None
    problem: str | None = None


@dataclass
class SdoTransaction:
    """One SDO read (`upload`) or write (`download`), emitted when it ends.

    `result` is `ok`, `abort`, `timeout` or `protocol_error`; `ref` is the opaque
    row reference of the frame that ended it (the caller's, not ours).
    """

    t_start: float
    t: float
    node: int
    channel: tuple[int, int]
    direction: str | None = None  # "upload" (read) / "download" (write); None: unknown
    protocol: str | None = None  # "expedited", "segmented", "block"
    index: int | None = None
    subindex: int | None = None
    size: int | None = None
    data: str | None = None
    value: int | float | str | bool | None = None
    name: str | None = None
    result: str = "ok"
    abort_code: int | None = None
    abort_text: str | None = None
    detail: str | None = None
    latency_ms: float | None = None
    words: str | None = None  # the value in words (decode/sdo/words.py), when there are any
    frames: int = 0
    ref: int | None = None
    problems: list[str] = field(default_factory=list)
    kind: str = "sdo"

    def to_record(self) -> dict:
        """JSON-ready dict with the stable keys of the `sdo` JSONL record."""
        return {
            "kind": self.kind,
            "t_start": self.t_start,
            "t": self.t,
            "latency_ms": None if self.latency_ms is None else round(self.latency_ms, 3),
            "node": self.node,
            "direction": self.direction,
            "protocol": self.protocol,
            "index": self.index,
            "subindex": self.subindex,
            "size": self.size,
            "data": self.data,
            "value": self.value,
            "name": self.name,
            "result": self.result,
            "abort_code": self.abort_code,
            "abort_text": self.abort_text,
            "detail": self.detail,
            "words": self.words,
            "frames": self.frames,
            "cob_ids": list(self.channel),
        }
