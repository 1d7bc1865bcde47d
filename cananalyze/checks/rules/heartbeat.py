"""Heartbeat rules: dropouts against 0x1017, heartbeats that stop, consumer time expiry.

Each heartbeat is judged by the 0x1017 in force at its time; a new value or a boot-up
restarts the producer's timer, so a gap across one is judged from there, and an NMT
reset command (to the node or to all) gives the node RESET_ANSWER_S to boot. 0x1017 = 0
means no heartbeat is expected. Where nothing is configured the expected period is
learned from the node's median gap, per segment between configuration changes and
resets (never across one), and the finding says so. One gap is one finding: a
dropout that also expires a consumer's 0x1016 says both in one.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.checks.spans import crossing, runs
from cananalyze.checks.spool import KeyedSpool
from cananalyze.config.timeline import RESET_ANSWER_S

MIN_LEARN = 5  # gaps a segment needs before its median is an expected period


def _is_in(t: float, times: np.ndarray) -> bool:
    """Whether `t` is one of the sorted `times`."""
    k = int(np.searchsorted(times, t))
    return k < times.size and times[k] == t


class HeartbeatRule(Rule):
    name = "heartbeat"
    needs_gaps = ("heartbeat",)  # finish() learns periods from every gap (Timing.all_gaps)
    why = (
        "A node whose heartbeat is late looks dead to its consumers, which then stop or fault; "
        "check the node's load, its 0x1017 setting and the bus load at that moment."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.last_seen: dict[int, float] = {}
        # node -> start times of the gaps judged without a known period (no 0x1017 known
        # at that time): finish() learns the period for these from the segment's median
        self.unjudged = KeyedSpool(1)  # on disk past a buffer: a long log has millions
        self.reported: dict[int, set[float]] = {}  # node -> gap starts already reported
        self.silent: dict[int, float] = {}  # node -> the silence tick() reported, from t
        self._limits: dict[tuple[int, int], dict] = {}  # _consumer_limits per stretch
        # node -> (last heartbeat, the finding tick() made while the silence lasted):
        # completed when the silence ends, so every output at exit has the whole gap
        self._open: dict[int, tuple] = {}  # + the tick's note that no frame came at all
        self._now: float | None = None  # live: the bus's clock at the latest tick

    def process(self, ctx: Context) -> None:
        g = ctx.gaps("heartbeat")
        if g.key.size == 0:
            return
        gap = g.gap
        for node, sl in g.groups():
            self.subjects.add(node)
            t, prev = g.t[sl], g.prev[sl]
            self.last_seen[node] = float(t[-1])
            deadline, period = self._deadlines(ctx, node, prev, t)
            unknown = np.isnan(deadline) & ~np.isnan(prev)
            if unknown.any():
                self.unjudged.add(node, prev[unknown])
            bad = np.flatnonzero(t > deadline) + sl.start
            for i in self.capped(bad, g.prev[bad], node, 0x700 + node).tolist():
                start = float(g.prev[i])
                text = (
                    f"heartbeat dropout: no heartbeat for {ms(gap[i])} ms from {ctx.rel(start)}"
                    + self._consumer_note(ctx, node, start, float(gap[i]))
                )
                if self._seen(node, start):  # tick() reported it while it lasted
                    self._complete(node, start, start, text, ms(gap[i]), ctx.t0)
                    continue
                self.emit(
                    start,
                    node,
                    0x700 + node,
                    text,
                    ms(gap[i]),
                    float(period[i - sl.start]),
                    row=g.row[i],
                    basis=ctx.config.origin(node, 0x1017, 0, start, ctx.t0),
                )
        self._consumers(ctx, g)

    def _complete(self, node: int, last: float, t: float, text: str, measured, t0) -> None:
        """Complete the finding tick() made for the silence after `last`, now that it
        ended (the next heartbeat, or the end): its time, text and measured gap."""
        opened = self._open.get(node)
        if opened is not None and opened[0] == last:
            del self._open[node]
            f = opened[1]
            f.t, f.message, f.measured = t, text, measured
            f.t_rel = t - (t0 if t0 is not None else t)

    def _seen(self, node: int, start: float) -> bool:
        """Whether a silence from `start` was reported (marks it reported if not)."""
        seen = self.reported.setdefault(node, set())
        if start in seen:
            return True
        seen.add(start)
        return False

    def _due(self, start: float, period: float | None) -> float:
        """When the next heartbeat is late, from `start` (NaN: unknown, inf: 0x1017 is 0)."""
        if period is None:
            return np.nan
        return np.inf if period == 0 else start + self.late(period) / 1000.0

    def _deadlines(self, ctx: Context, node: int, prev, t) -> tuple[np.ndarray, np.ndarray]:
        """Per heartbeat, when it was late at the latest, and the period in force (ms)."""
        changes = ctx.config.changes(node, 0x1017, 0x1017)
        deadline = np.full(t.size, np.nan)
        period = np.full(t.size, np.nan)
        across = crossing(changes, prev, t)
        for sl, at in runs(changes, t):
            p = ctx.config.heartbeat_ms(node, at)
            if p is None:
                continue
            inside = ~across[sl]
            period[sl][inside] = p
            deadline[sl][inside] = np.inf if p == 0 else prev[sl][inside] + self.late(p) / 1000.0
        for i in np.flatnonzero(across & ~np.isnan(prev)).tolist():
            start = float(prev[i])
            due, p, _ = self._deadline(ctx, node, start, changes, float(t[i]))
            if t[i] <= due and ctx.config.heartbeat_ms(node, start) is None:
                due = np.nan  # began with 0x1017 unknown: the segment's median judges it
            deadline[i], period[i] = due, np.nan if p is None else p
        return deadline, period

    def _deadline(self, ctx: Context, node: int, start: float, changes, until: float):
        """(deadline, period, start of its stretch) after a heartbeat at `start`, following
        the changes up to `until`: a new 0x1017 or a boot-up restarts the producer's timer;
        an NMT reset command gives the node RESET_ANSWER_S to boot before its timer runs."""
        p = ctx.config.heartbeat_ms(node, start)
        due = self._due(start, p)
        commands = ctx.config.reset_commands(node)
        for c in changes[(changes > start) & (changes <= until)].tolist():
            if c > due:  # late before the change (NaN: not known, so go on)
                break
            start, p = c, ctx.config.heartbeat_ms(node, c)
            due = self._due(c, p)
            if p and _is_in(c, commands):
                due += RESET_ANSWER_S
        return due, p, start

    def _consumer_limits(self, ctx: Context, at: float) -> dict[int, list[tuple[int, float]]]:
        """producer -> [(consumer, consumer time ms)] of the 0x1016 entries in force at `at`
        (asked once per stretch between 0x1016 changes)."""
        changes = ctx.config.changes(None, 0x1016, 0x1016)
        key = (changes.size, int(np.searchsorted(changes, at, side="right")))
        cached = self._limits.get(key)
        if cached is not None:
            return cached
        consumers: dict[int, list[tuple[int, float]]] = {}
        for consumer in range(1, 128):
            for producer, limit in ctx.config.heartbeat_consumers(consumer, at).items():
                consumers.setdefault(producer, []).append((consumer, limit))
        if len(self._limits) > 64:
            self._limits.clear()
        self._limits[key] = consumers
        return consumers

    def _consumer_note(self, ctx: Context, node: int, start: float, gap_s: float) -> str:
        """The consumers a dropout also expired, said in the dropout's finding."""
        hit = [
            f"node {c}'s consumer time {limit:g} ms"
            for c, limit in self._consumer_limits(ctx, start).get(node, ())
            if gap_s > limit / 1000.0
        ]
        return f"; expired {', '.join(hit)}" if hit else ""

    def _consumers(self, ctx: Context, g) -> None:
        """0x1016 consumer time expiry, judged by the entries in force at each heartbeat
        (a gap already reported as a dropout names its consumers there)."""
        changes = ctx.config.changes(None, 0x1016, 0x1016)
        gap = g.gap
        for sl_run, at in runs(changes, g.t):
            consumers = self._consumer_limits(ctx, at)
            if not consumers:
                continue
            across = crossing(changes, g.prev[sl_run], g.t[sl_run])
            for node, sl in g.groups():
                lo, hi = max(sl.start, sl_run.start), min(sl.stop, sl_run.stop)
                reported = self.reported.get(node, set())
                for consumer, limit_ms in consumers.get(node, ()) if lo < hi else ():
                    late = (gap[lo:hi] > limit_ms / 1000.0) & ~across[
                        lo - sl_run.start : hi - sl_run.start
                    ]
                    for i in (np.flatnonzero(late) + lo).tolist():
                        if float(g.prev[i]) in reported:
                            continue
                        self.emit(
                            g.prev[i] + limit_ms / 1000.0,
                            node,
                            0x700 + node,
                            f"node {consumer}'s heartbeat consumer time for node {node} expired "
                            f"(gap {ms(gap[i])} ms)",
                            ms(gap[i]),
                            limit_ms,
                            row=g.row[i],
                            why="The consumer raises a heartbeat event (usually an EMCY 0x8130 "
                            "and a fault reaction); check the producer and the consumer time "
                            "in 0x1016.",
                            basis=ctx.config.consumer_origin(
                                consumer, node, float(g.prev[i]), ctx.t0
                            ),
                        )
                        self.reported.setdefault(node, set()).add(float(g.prev[i]))

    def _learned(self, ctx: Context, node: int, changes: np.ndarray):
        """Per segment between changes and resets: (start, end, median ms) of the gaps
        wholly inside it, for segments with MIN_LEARN gaps or more. Gaps of zero (frames
        that share a time stamp: a logger's coarse clock, or frames that only share the
        identifier) are no period: a median of them would call every real gap late."""
        t, gaps = ctx.timing.all_gaps("heartbeat", node)
        if gaps.size == 0:
            return t, gaps, np.zeros(0, np.intp), {}
        seg = np.searchsorted(changes, t, side="right")
        inside = seg == np.searchsorted(changes, t + gaps, side="right")
        out: dict[int, tuple[float, float, float]] = {}
        for k in np.unique(seg[inside]).tolist():
            mine = inside & (seg == k) & (gaps > 0)
            if np.count_nonzero(mine) >= MIN_LEARN:
                tk = t[mine]
                end = float(tk[-1] + gaps[mine][-1])
                out[k] = (float(tk[0]), end, float(np.median(gaps[mine])) * 1000.0)
        return t, gaps, seg, out

    def _learned_limit(self, median_ms: float) -> float:
        """A learned period is a guess: late at twice the median (or the tolerance, if wider)."""
        return max(2.0 * median_ms, self.late(median_ms))

    def _learned_dropouts(self, ctx: Context, node: int, changes, t, gaps, seg, learned) -> None:
        """The gaps judged without a known 0x1017, against their segment's median, as
        columns: a jittery node on a long log has thousands. Not end-of-log results:
        the terminal caps them like the others."""
        cand = np.flatnonzero(np.isin(t, self.unjudged.get(node)[0]))
        segs = seg[cand]
        known = np.isin(segs, np.fromiter(learned, np.int64, len(learned)))
        cand, segs = cand[known], segs[known]
        if cand.size == 0:
            return
        # each segment's limit, looked up per gap (a long log has hundreds of thousands)
        keys = np.fromiter(learned, np.int64, len(learned))
        limits = np.array([self._learned_limit(m) / 1000.0 for _, _, m in learned.values()])
        # a gap across a change is judged only up to the change
        upto = np.full(cand.size, np.inf)
        inside = segs < changes.size
        upto[inside] = changes[segs[inside]]
        by_key = np.argsort(keys)
        limit = limits[by_key][np.searchsorted(keys[by_key], segs)]  # every seg is a key
        over = np.minimum(gaps[cand], upto - t[cand]) > limit
        # ... unless the change is an NMT reset command: then the node owes its boot-up
        # (the next change) within RESET_ANSWER_S, and a heartbeat a period after that
        commands = ctx.config.reset_commands(node)
        reset = inside & np.isin(upto, commands)
        if reset.any():
            after = np.append(changes, np.inf)[np.minimum(segs + 1, changes.size)]
            waited = np.minimum(t[cand] + gaps[cand], after) - upto
            over |= reset & (waited > RESET_ANSWER_S + limit)
        cand = cand[over]
        seg_list = segs[over].tolist()
        fresh = [not self._seen(node, v) for v in t[cand].tolist()]
        if not any(fresh):
            return
        cand = cand[fresh]
        seg_list = [k for k, f in zip(seg_list, fresh, strict=True) if f]
        rel = ctx.rel
        basis = {
            k: f"learned from the log's median over {rel(lo)}..{rel(hi)}"
            for k, (lo, hi, _) in learned.items()
        }
        tc, gc = t[cand], gaps[cand]

        def text(k: np.ndarray) -> list[str]:
            return [
                f"heartbeat dropout: no heartbeat for {ms(g)} ms from {rel(s)} "
                "(0x1017 not known: period learned)"
                for g, s in zip(gc[k].tolist(), tc[k].tolist(), strict=True)
            ]

        self.emit_many(
            tc,
            node,
            0x700 + node,
            text,
            [ms(g) for g in gc.tolist()],
            [round(learned[k][2], 3) for k in seg_list],
            severity="warning",
            basis=[basis[k] for k in seg_list],
            at_end=False,
        )

    def finish(self, ctx: Context) -> None:
        for node, last in sorted(self.last_seen.items()):
            changes = ctx.config.changes(node, 0x1017, 0x1017)
            end = ctx.t_end if ctx.t_end is not None else last
            due, period, start = self._deadline(ctx, node, last, changes, end)
            basis = ctx.config.origin(node, 0x1017, 0, start, ctx.t0) if period else ""
            t, gaps, seg, learned = self._learned(ctx, node, changes)
            if node in self.unjudged and learned:
                self._learned_dropouts(ctx, node, changes, t, gaps, seg, learned)
            if period is None:  # not known at the end: the last segment's median says when
                got = learned.get(int(np.searchsorted(changes, last, "right")))
                if got is not None and start == last:
                    lo, hi, period = got
                    due = last + self._learned_limit(period) / 1000.0
                    basis = f"learned from the log's median over {ctx.rel(lo)}..{ctx.rel(hi)}"
            if period and ctx.t_end is not None and ctx.t_end > due:
                text = (
                    f"heartbeat stopped: last one at {ctx.rel(last)}, log goes on for "
                    f"{ms(ctx.t_end - last)} ms"
                )
                if node in self.silent and self.silent[node] == last:  # live: seen already
                    at = start + period / 1000.0
                    self._complete(node, last, at, text, ms(ctx.t_end - last), ctx.t0)
                    continue
                self.emit(
                    start + period / 1000.0,
                    node,
                    0x700 + node,
                    text,
                    ms(ctx.t_end - last),
                    round(period, 3),
                    why="The node fell silent (power, reset loop, bus-off or crash); check its supply "
                    "and whether it went bus-off (error frames just before).",
                    basis=basis,
                )
            opened = self._open.pop(node, None)
            if opened is not None and opened[0] == last and self._now is not None:
                # live, never back, no frame after it: silent until the session ended
                f = opened[1]
                f.measured = ms(self._now - last)
                f.message = (
                    f"heartbeat stopped: none since {ctx.rel(last)} ({f.measured} ms until "
                    f"the session ended){opened[2]}"
                )

    def tick(self, ctx: Context, now: float) -> None:
        """Live: a node whose configured heartbeat is overdue at `now`, reported once."""
        self._now = now
        for node, last in sorted(self.last_seen.items()):
            if self.silent.get(node) == last:
                continue
            changes = ctx.config.changes(node, 0x1017, 0x1017)
            due, period, start = self._deadline(ctx, node, last, changes, now)
            if not period or not now > due:
                continue
            self.silent[node] = last
            self.reported.setdefault(node, set()).add(last)
            n = len(self.out)
            quiet = self.quiet(ctx, due)
            self.emit(
                now,
                node,
                0x700 + node,
                f"heartbeat stopped: none since {ctx.rel(last)} ({ms(now - last)} ms so far)"
                + quiet,
                ms(now - last),
                float(period),
                why="The node fell silent (power, reset loop, bus-off or crash); check its supply "
                "and whether it went bus-off (error frames just before).",
                basis=ctx.config.origin(node, 0x1017, 0, start, ctx.t0),
            )
            if len(self.out) > n:
                self._open[node] = (last, self.out[-1], quiet)
