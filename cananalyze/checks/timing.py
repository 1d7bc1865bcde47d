"""Timing analysis: heartbeat, PDO and SYNC periods, SDO latency, EMCY and boot-up counts.

Fed by the Checker's per-batch gap tables (numpy diffs per node / COB-ID, carried
across batches). Each stream's statistics are kept in a `StreamStats` (exact count,
min, max, mean and jitter; median and p99 exact up to 4096 values, then within
0.1 %), so memory does not grow with the log. Only gap tables a rule asks for in
`keep` (the heartbeat rule infers periods after the fact) keep every gap.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from cananalyze.checks.rule import Context
from cananalyze.checks.spans import pdo_stretches, sync_before
from cananalyze.checks.spool import KeyedSpool
from cananalyze.checks.streamstats import StreamStats, bins_of, histogram_many
from cananalyze.core.finding import rel_time
from cananalyze.protocol.services import Service


class Timing:
    def __init__(self, keep: set[str] | frozenset[str] = frozenset(), stats: bool = True) -> None:
        """`stats`: keep each stream's gap statistics (the `--timing` and summary report);
        without, only counts, spans and the kept gaps the rules read (half the checks'
        cost in an export, where nobody prints the report)."""
        self.keep = set(keep)  # gap tables whose every gap is kept (for all_gaps)
        self.with_stats = stats
        self.stats: dict[str, dict[int, StreamStats]] = {"heartbeat": {}, "pdo": {}, "sync": {}}
        # the kept tables' (gap start, gap in s) per key, on disk past a buffer (flat memory)
        self.gaps: dict[str, KeyedSpool] = {name: KeyedSpool(2) for name in self.keep}
        self.count: dict[str, Counter] = {
            "heartbeat": Counter(),
            "pdo": Counter(),
            "sync": Counter(),
        }
        self.span: dict[str, dict[int, list[float]]] = {"heartbeat": {}, "pdo": {}, "sync": {}}
        self.emcy: Counter = Counter()
        self.bootups: Counter = Counter()
        self.sdo_latency: dict[int | None, StreamStats] = {}
        # synchronous PDOs (types 0-240) after the SYNC before each: per COB-ID, and what
        # it is (node, direction, number, type) with the window 0x1007 at its last frame
        self.sync_latency: dict[int, StreamStats] = {}
        self.sync_pdo: dict[int, tuple] = {}
        self._last_sync_t = np.nan
        self.sdo_results: Counter = Counter()
        self.error_frames = 0

    def update(self, ctx: Context) -> None:
        b = ctx.batch
        if len(b) == 0:
            return
        for name in ("heartbeat", "pdo", "sync"):
            g = ctx.gaps(name)
            if g.key.size == 0:
                continue
            self._update_table(name, g)
        emcy = b.node[ctx.rows(Service.EMCY)]
        if emcy.size:
            self.emcy.update(emcy.tolist())
        boot = b.node[ctx.rows(Service.BOOTUP)]
        if boot.size:
            self.bootups.update(boot.tolist())
        self.error_frames += int(ctx.rows(Service.ERROR_FRAME).size)
        self._sync_latency(ctx)  # few streams: kept in exports too (load().sync_latency)
        if b.records:
            self._sdo(b)

    def _sync_latency(self, ctx: Context) -> None:
        """Each synchronous PDO (transmission type 0-240 in force at its time, TPDO or
        RPDO) after the latest SYNC before it, per COB-ID; the window 0x1007 in force at
        its last frame beside it. The pdo_sync rule judges the same PDOs by the window."""
        srows = ctx.rows(Service.SYNC)
        st = ctx.batch.frames.t[srows]
        g = ctx.gaps("pdo")
        if g.key.size and ctx.timed:
            for cob, (node, pdo), idx, _ in pdo_stretches(ctx, g):
                if pdo.transmission_type > 240:
                    continue
                t = g.t[idx]
                _, last_t = sync_before(srows, st, g.row[idx], self._last_sync_t)
                late = (t - last_t) * 1000.0
                b = ctx.batch  # each frame's latency, for the frames table
                if b.sync_latency is None:
                    b.sync_latency = np.full(len(b), np.nan)
                b.sync_latency[g.row[idx]] = late
                late = late[~np.isnan(late)]
                stats = self.sync_latency.get(cob)
                if stats is None:
                    stats = self.sync_latency[cob] = StreamStats()
                if late.size:
                    stats.add(late)
                window = ctx.config.sync_window_us(float(t[-1]))
                what = (node, pdo.direction, pdo.number, pdo.transmission_type)
                self.sync_pdo[cob] = (*what, window / 1000 if window else None)
        if st.size:
            self._last_sync_t = float(st[-1])

    def _sdo(self, b) -> None:
        """Result counts and latency per node, from the batch's SDO records as columns."""
        tab = b.records.table()
        if tab.node.size == 0:
            return
        counts = np.bincount(tab.result, minlength=len(tab.result_keys)).tolist()
        # Counter order as counting the records one by one gives (first seen first)
        self.sdo_results.update({tab.result_keys[r]: counts[r] for r in tab.first_seen(tab.result)})
        for c, at in tab.groups(tab.node, ~np.isnan(tab.latency)):
            node = tab.node_keys[c]
            st = self.sdo_latency.get(node)
            if st is None:
                st = self.sdo_latency[node] = StreamStats()
            st.add(tab.latency[at])

    def _update_table(self, name: str, g) -> None:
        """Counts, spans and gap statistics of one gap table: moments per key in one pass."""
        keep = bool(self.keep) and name in self.keep
        if self.with_stats or keep:  # an export's PDO table needs neither: no gap read
            v, key, first, t_prev, gap_s = self._judged_gaps(g, self.with_stats)
            if v.size and not self.with_stats:
                ends = np.r_[first[1:], v.size].tolist()
                for a, e, key_j in zip(first.tolist(), ends, key[first].tolist(), strict=True):
                    self.gaps[name].add(key_j, t_prev[a:e], gap_s[a:e])
            elif v.size:
                self._add_stats(name, v, key, first, t_prev, gap_s, keep)
        self._count_spans(name, g)

    @staticmethod
    def _judged_gaps(g, in_ms: bool) -> tuple:
        """(gaps in ms, keys, start of each key's run, previous times, gaps in s) of the
        table's frames that have a gap (a stream's first frame ever has none); the gaps in
        ms only when `in_ms`."""
        gap = g.gap
        nan = np.isnan(gap)
        if not nan.any():  # the steady state: every key seen before, the table's own groups
            return (gap * 1000.0 if in_ms else gap), g.key, g.starts, g.prev, gap
        ok = ~nan
        key, gap_s = g.key[ok], gap[ok]
        first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        return (gap_s * 1000.0 if in_ms else gap_s), key, first, g.prev[ok], gap_s

    def _add_stats(self, name: str, v, key, first, t_prev, gap_s, keep: bool) -> None:
        """Merge each key's batch moments and values into its StreamStats (and keep its
        gaps when `keep`)."""
        streams = self.stats[name]
        k = np.diff(np.r_[first, v.size])
        mean = np.add.reduceat(v, first) / k
        dev = v - np.repeat(mean, k)
        m2 = np.add.reduceat(dev * dev, first)
        lo, hi = np.minimum.reduceat(v, first), np.maximum.reduceat(v, first)
        ends = (first + k).tolist()
        binned: list[tuple[StreamStats, int, int]] = []  # streams past EXACT: one bincount
        for a, e, key_j, mean_j, m2_j, lo_j, hi_j in zip(
            first.tolist(),
            ends,
            key[first].tolist(),
            mean.tolist(),
            m2.tolist(),
            lo.tolist(),
            hi.tolist(),
            strict=True,
        ):
            st = streams.get(key_j)
            if st is None:
                st = streams[key_j] = StreamStats()
            st.add_moments(e - a, mean_j, m2_j, lo_j, hi_j)
            if st.exact:
                st.add_values(v[a:e])
            else:
                binned.append((st, a, e))
            if keep:
                self.gaps[name].add(key_j, t_prev[a:e], gap_s[a:e])
        if binned:
            histogram_many(binned, v, bins_of(v))

    def _count_spans(self, name: str, g) -> None:
        """Frames and first/last time per key; a key with one frame so far is listed with
        no gaps. Per key, from lists (not a numpy scalar per key)."""
        count, span, streams = self.count[name], self.span[name], self.stats[name]
        starts = g.starts
        ends = np.r_[starts[1:], g.key.size]
        for key_j, n, t_a, t_e in zip(
            g.key[starts].tolist(),
            (ends - starts).tolist(),
            g.t[starts].tolist(),
            g.t[ends - 1].tolist(),
            strict=True,
        ):
            if key_j not in streams:
                streams[key_j] = StreamStats()
            count[key_j] += n
            sp = span.get(key_j)
            if sp is None:
                span[key_j] = [t_a, t_e]
            else:
                sp[1] = t_e

    def all_gaps(self, name: str, key: int) -> tuple[np.ndarray, np.ndarray]:
        """(gap start times, gaps in s) of one node / COB-ID over the whole log.

        Only for gap tables in `keep`; the others keep statistics, not gaps.
        """
        if name not in self.keep:
            raise ValueError(f"Timing(keep=...) does not keep the {name} gaps")
        return self.gaps[name].get(key)

    def rate_hz(self, name: str, key: int) -> float | None:
        n = self.count[name].get(key, 0)
        sp = self.span[name].get(key)
        if n < 2 or not sp or sp[1] <= sp[0]:
            return None
        return (n - 1) / (sp[1] - sp[0])

    def report(self, nmt=None) -> dict:
        out: dict = {"heartbeat": {}, "pdo": {}, "sync": None}
        for node in sorted(self.stats["heartbeat"]):
            out["heartbeat"][node] = self.stats["heartbeat"][node].stats()
        for cob in sorted(self.stats["pdo"]):
            s = self.stats["pdo"][cob].stats()
            s["rate_hz"] = self.rate_hz("pdo", cob) if self.with_stats else None
            out["pdo"][cob] = s
        if self.stats["sync"]:
            out["sync"] = self.stats["sync"][0].stats()
        out["sync_latency"] = {}
        for cob in sorted(self.sync_latency):
            node, direction, number, ttype, window = self.sync_pdo[cob]
            s = self.sync_latency[cob].stats()
            s |= {"node": node, "pdo": f"{'t' if direction == 'tx' else 'r'}pdo{number}"}
            s["type"] = ttype
            s["window_ms"] = window
            s["margin_ms"] = window - s["max"] if window and s.get("count") else None
            out["sync_latency"][cob] = s
        out["sdo_latency"] = {n: st.stats() for n, st in self.sdo_latency.items()}
        out["sdo_results"] = dict(self.sdo_results)
        out["emcy"] = dict(self.emcy)
        out["bootups"] = dict(self.bootups)
        out["error_frames"] = self.error_frames
        if nmt is not None:
            out["nmt"] = nmt.timeline()
        return out

    def lines(self, nmt=None, t0: float | None = None, timed: bool = True) -> list[str]:
        """`--timing`'s lines. A log without times (`timed` False; the checks' times are
        then line numbers) has no periods, gaps nor latencies, and its states are told
        by line."""
        r = self.report(nmt)
        if not timed:
            r["heartbeat"], r["pdo"], r["sync"], r["sdo_latency"] = {}, {}, None, {}
            r["sync_latency"] = {}

        def fmt(s: dict) -> str:
            if not s.get("count"):
                return "no gaps"
            return (
                f"n={s['count']} min {s['min']:.2f} median {s['median']:.2f} mean {s['mean']:.2f} "
                f"p99 {s['p99']:.2f} max {s['max']:.2f} jitter {s['jitter']:.2f} ms"
            )

        out = []
        if not timed:
            out.append("periods, gaps and latencies: not known (the log has no timestamps)")
        if r["heartbeat"]:
            out.append("heartbeat period per node:")
            out += [f"  node {n:>3}: {fmt(s)}" for n, s in r["heartbeat"].items()]
        if r["sync"]:
            out.append(f"SYNC period: {fmt(r['sync'])}")
        if r["pdo"]:
            out.append("PDO gaps per COB-ID:")
            for cob, s in r["pdo"].items():
                rate = f" rate {s['rate_hz']:.2f} Hz" if s.get("rate_hz") else ""
                out.append(f"  0x{cob:03X}:{rate} {fmt(s)}")
        if r["sync_latency"]:
            out.append("synchronous PDOs, latency after SYNC per COB-ID:")
            for cob, s in r["sync_latency"].items():
                window = (
                    f"; window 0x1007 {s['window_ms']:g} ms, margin {s['margin_ms']:.2f} ms"
                    if s["margin_ms"] is not None
                    else ""
                )
                what = f"node {s['node']} {s['pdo'].upper()} type {s['type']}"
                out.append(f"  0x{cob:03X} ({what}): {fmt(s)}{window}")
        if r["sdo_latency"]:
            out.append("SDO latency per node:")
            out += [
                f"  node {n}: {fmt(s)}"
                for n, s in sorted(r["sdo_latency"].items(), key=_node_order)
            ]
        if any(not st.exact for table in self.stats.values() for st in table.values()) or any(
            not st.exact for st in self.sdo_latency.values()
        ):
            out.append(
                "(median and p99 of streams with more than 4096 values: from 0.1 % bins, "
                "within 0.1-0.4 %; the other figures exact)"
            )
        if r["emcy"]:
            out.append(
                "EMCY per node: "
                + ", ".join(f"node {n}: {c}" for n, c in sorted(r["emcy"].items()))
            )
        if r["bootups"]:
            out.append(
                "boot-ups per node: "
                + ", ".join(f"node {n}: {c}" for n, c in sorted(r["bootups"].items()))
            )
        if r["error_frames"]:
            out.append(f"error frames: {r['error_frames']}")
        for node, changes in (r.get("nmt") or {}).items():
            steps = ", ".join(
                f"{rel_time(t, t0) if timed else f'line {t:.0f}'} {s} ({src})"
                for t, s, src in changes[:12]
            )
            more = f", ... {len(changes) - 12} more" if len(changes) > 12 else ""
            out.append(f"NMT state node {node}: {steps}{more}")
        return out


def _node_order(item: tuple) -> tuple:
    """Node-IDs in number order (10 after 9, not after 1), names after them."""
    key = item[0]
    return (0, key, "") if isinstance(key, int) else (1, 0, str(key))
