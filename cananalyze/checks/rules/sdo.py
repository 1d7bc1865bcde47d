"""SDO transfers (from the SDO tracker's records): aborts, timeouts, protocol errors, slow
replies; and a master's node-ID scan, reported once instead of one timeout per absent node."""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.senders import senders
from cananalyze.protocol.sdo import object_text

# A scan: unanswered reads of one object by at least this many node-IDs that never sent a
# frame (python-canopen's `scanner.search()` and commissioning tools probe 1..127); the
# timeouts of a smaller group are findings, once no further probe came for SCAN_QUIET_S.
SCAN_MIN = 8
SCAN_QUIET_S = 10.0
# live, a timeout is not held longer than this past the last one of its object: a scanner
# sends its probes in one burst (their timeouts come together), and an engineer watching
# the bus hears of one unanswered read at once; a scan spread wider than this is reported
# live as its timeouts (a file keeps SCAN_QUIET_S)
LIVE_QUIET_S = 0.2


class _Scan:
    """One object's scan: when, which node-IDs it probed, how many rounds (a node-ID
    probed again starts the next)."""

    def __init__(self, t: float) -> None:
        self.t = self.end = t
        self.probed: set[int] = set()
        self._round: set[int] = set()
        self.rounds = 1

    def probe(self, node: int, t: float) -> None:
        if node in self._round:
            self.rounds += 1
            self._round.clear()
        self._round.add(node)
        self.probed.add(node)
        self.end = max(self.end, t)


def _ranges(nodes: list[int]) -> str:
    """1-3, 7, 9-127."""
    out, start = [], None
    for a, b in zip(nodes, nodes[1:] + [None], strict=True):
        start = a if start is None else start
        if b != a + 1:
            out.append(f"{start}" if start == a else f"{start}-{a}")
            start = None
    return ", ".join(out)


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
        self._seen: set[int] = set()  # node-IDs that sent a frame so far
        # timeouts of reads to node-IDs never seen, by object: held until they make a scan
        self._held: dict[tuple[int, int], list[tuple[int, dict]]] = {}
        self._scans: dict[tuple[int, int], _Scan] = {}
        # the first successful read of each object from each node: (node, index, sub) key
        # -> (time, value), for the nodes that answered a scan
        self._answers: dict[int, tuple[float, object]] = {}

    def _see(self, ctx: Context) -> None:
        """Which node-IDs sent a frame, and what each first answered to a read."""
        self._seen.update(senders(ctx.batch).tolist())
        recs = ctx.batch.records
        if not recs:
            return
        c = recs.cols
        ok = np.flatnonzero(c.ok & c.upload & (c.node >= 0))
        if not ok.size:
            return
        key = (c.node[ok].astype(np.int64) << 24) | (c.index[ok].astype(np.int64) << 8)
        key |= c.subindex[ok]
        keys, first = np.unique(key, return_index=True)
        for k, at in zip(keys.tolist(), first.tolist(), strict=True):
            if k not in self._answers:  # one dict built per node and object, not per read
                rec = recs.record(int(ok[at]))
                self._answers[k] = (rec.get("t_start", rec.get("t", 0.0)), rec.get("value"))

    def _hold(self, ctx: Context, row: int, rec: dict) -> bool:
        """Whether a timeout is a scan's probe (or may be): a read of a node-ID that never
        sent a frame and that the user did not declare."""
        node = rec.get("node")
        if (
            rec.get("result") != "timeout"
            or rec.get("direction") != "upload"
            or not isinstance(node, int)
            or node in self._seen
            or node in ctx.config.declared_nodes()
        ):
            return False
        obj = (rec.get("index", 0), rec.get("subindex", 0))
        t = rec.get("t_start", rec.get("t", 0.0))
        scan = self._scans.get(obj)
        if scan is not None:
            scan.probe(node, t)
            return True
        held = self._held.setdefault(obj, [])
        held.append((row, rec))
        nodes = {r["node"] for _, r in held}
        if len(nodes) >= SCAN_MIN:
            scan = self._scans[obj] = _Scan(held[0][1].get("t_start", t))
            for _, r in held:
                scan.probe(r["node"], r.get("t_start", r.get("t", 0.0)))
            del self._held[obj]
        return True

    def _release(self, ctx: Context, before: float | None, quiet: float = SCAN_QUIET_S) -> None:
        """Held timeouts that made no scan (their last `quiet` before `before`; all at the
        end): findings."""
        for obj in list(self._held):
            held = self._held[obj]
            if before is not None and held[-1][1].get("t", 0.0) >= before - quiet:
                continue
            del self._held[obj]
            for _, rec in held:
                self._finding(ctx, 0, rec)

    def tick(self, ctx: Context, now: float) -> None:
        self._release(ctx, now, LIVE_QUIET_S)

    def finish(self, ctx: Context) -> None:
        self._release(ctx, None)
        for (index, sub), scan in self._scans.items():
            answered = {}
            for key, (t, value) in self._answers.items():
                node = key >> 24
                if (key >> 8) & 0xFFFF == index and key & 0xFF == sub and t <= scan.end + 1.0:
                    answered[node] = value
            probed = sorted(scan.probed | set(answered))
            said = ", ".join(
                f"node {n}" + (f" (0x{v:08X})" if isinstance(v, int) else "")
                for n, v in sorted(answered.items())
            )
            times = f"{scan.rounds} times, " if scan.rounds > 1 else ""
            self.emit(
                scan.t,
                None,
                None,
                f"node-ID scan: SDO read of {object_text(index, sub)} to {len(probed)} node-IDs "
                f"({_ranges(probed)}), {times}from {ctx.rel(scan.t)} to {ctx.rel(scan.end)}; "
                f"answered: {said or 'none'}; the {len(scan.probed)} others sent nothing in "
                "the log (absent, not a fault)",
                len(answered),
                len(probed),
                severity="info",
                why="A master probing every node-ID (a scan) expects most of them to stay "
                "silent; their unanswered reads are not SDO timeouts.",
                basis=f"scan: unanswered reads of one object by {SCAN_MIN} or more node-IDs "
                "that sent nothing and are not declared",
            )

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
        self._see(ctx)
        if self._held and len(ctx.batch):
            self._release(ctx, ctx.t_first)
        for row, rec in self._picked(ctx.batch):
            if rec.get("kind") != "sdo":
                continue
            self.subjects.add(rec.get("node"))
            if self._hold(ctx, row, rec):
                continue
            self._finding(ctx, row, rec)

    def _finding(self, ctx: Context, row: int, rec: dict) -> None:
        """The findings of one transfer: failed, or slower than max_latency_ms."""
        node = rec.get("node")
        result = rec.get("result")
        lat = rec.get("latency_ms")
        slow = (
            ctx.timed
            and self.max_latency is not None
            and lat is not None
            and lat > self.max_latency
        )
        if result == "ok" and not slow:
            return  # the usual case: nothing to format
        obj = object_text(rec.get("index", 0), rec.get("subindex", 0))
        what = f"{rec.get('direction') or 'transfer'} {obj}"
        # CiA 1301's USDO (protocol usdo_*): the same rule, its one-byte abort codes
        usdo = str(rec.get("protocol") or "").startswith("usdo")
        svc = "USDO" if usdo else "SDO"
        if result and result != "ok":
            detail = rec.get("abort_text") or rec.get("detail") or ""
            if rec.get("direction") is None and rec.get("abort_text") and rec.get("detail"):
                detail += f" [{rec['detail']}]"  # which COB-ID, and that its start is not here
            code = rec.get("abort_code")
            width = 2 if usdo else 8
            measured = f"0x{code:0{width}X}" if isinstance(code, int) else result
            self.emit(
                rec.get("t", 0.0),
                node,
                None,
                f"{svc} {what} {result}: {detail}".rstrip(": "),
                measured,
                "ok",
                row=row,
            )
        if slow:
            self.emit(
                rec.get("t", 0.0),
                node,
                None,
                f"{svc} {what} took {lat:g} ms",
                lat,
                self.max_latency,
                row=row,
                basis="max_latency_ms in the rules file",
                why="A slow SDO server stalls configuration and may hit the master's timeout; "
                "check the node's load and the bus load.",
            )
