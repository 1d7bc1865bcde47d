"""SDO transfers (from the SDO tracker's records): aborts, timeouts, protocol errors, slow replies."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.protocol.sdo import object_text


class SdoRule(Rule):
    name = "sdo"
    timing = False  # judged by frame order: kept on logs without timestamps
    why = (
        "A failed SDO transfer means a parameter was not read or written as the master assumed; "
        "check the abort code against the object dictionary (object exists, access, value range)."
    )

    def __init__(self, max_latency_ms: float | None = None, **kw) -> None:
        super().__init__(**kw)
        self.max_latency = max_latency_ms

    def _picked(self, batch) -> list:
        """Records that may need a finding, in order: the ok, quick ones skipped."""
        recs = batch.records
        tab = recs.table()
        for c in tab.first_seen(tab.node):  # the order a loop over the records adds them in
            self.subjects.add(tab.node_keys[c])
        cols = recs.cols
        flag = ~cols.ok
        if self.max_latency is not None:
            flag |= cols.latency > self.max_latency
        return recs.picked(np.flatnonzero(flag).tolist())

    def process(self, ctx: Context) -> None:
        subjects = self.subjects
        picked = self._picked(ctx.batch)
        for row, rec in picked:
            if rec.get("kind") != "sdo":
                continue
            node = rec.get("node")
            subjects.add(node)
            result = rec.get("result")
            lat = rec.get("latency_ms")
            slow = (
                ctx.timed
                and self.max_latency is not None
                and lat is not None
                and lat > self.max_latency
            )
            if result == "ok" and not slow:
                continue  # the usual case: nothing to format
            obj = object_text(rec.get("index", 0), rec.get("subindex", 0))
            what = f"{rec.get('direction') or 'transfer'} {obj}"
            if result and result != "ok":
                detail = rec.get("abort_text") or rec.get("detail") or ""
                if rec.get("direction") is None and rec.get("abort_text") and rec.get("detail"):
                    detail += f" [{rec['detail']}]"  # which COB-ID, and that its start is not here
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
                    basis="max_latency_ms in the rules file",
                    why="A slow SDO server stalls configuration and may hit the master's timeout; "
                    "check the node's load and the bus load.",
                )
