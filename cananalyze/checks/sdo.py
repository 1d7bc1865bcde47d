"""SDO transfers (from the SDO tracker's records): aborts, timeouts, protocol errors, slow replies."""

from __future__ import annotations

from .rule import Context, Rule


class SdoRule(Rule):
    name = "sdo"
    why = (
        "A failed SDO transfer means a parameter was not read or written as the master assumed; "
        "check the abort code against the object dictionary (object exists, access, value range)."
    )

    def __init__(self, max_latency_ms: float | None = None, **kw) -> None:
        super().__init__(**kw)
        self.max_latency = max_latency_ms

    def process(self, ctx: Context) -> None:
        subjects = self.subjects
        for row, rec in list(ctx.batch.records):
            if rec.get("kind") != "sdo":
                continue
            node = rec.get("node")
            subjects.add(node)
            result = rec.get("result")
            lat = rec.get("latency_ms")
            slow = self.max_latency is not None and lat is not None and lat > self.max_latency
            if result == "ok" and not slow:
                continue  # the usual case: nothing to format
            what = f"{rec.get('direction')} {rec.get('index', 0):04X}:{rec.get('subindex', 0):02X}"
            if result and result != "ok":
                detail = rec.get("abort_text") or rec.get("detail") or ""
                code = rec.get("abort_code")
                measured = f"0x{code:08X}" if isinstance(code, int) else result
                self.emit(
                    rec.get("t", 0.0),
                    node,
                    None,
                    f"SDO {what} {result}: {detail}".rstrip(": "),
                    measured,
                    "ok",
                    row=row,
                )
            if slow:
                self.emit(
                    rec.get("t", 0.0),
                    node,
                    None,
                    f"SDO {what} took {lat:g} ms",
                    lat,
                    self.max_latency,
                    row=row,
                    why="A slow SDO server stalls configuration and may hit the master's timeout; "
                    "check the node's load and the bus load.",
                )
