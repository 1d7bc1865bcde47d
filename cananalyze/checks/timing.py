"""Timing analysis: heartbeat, PDO and SYNC periods, SDO latency, EMCY and boot-up counts.

Fed by the Checker's per-batch gap tables (numpy diffs per node / COB-ID, carried
across batches); stores the gaps as arrays so medians and percentiles are exact.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from ..protocol.services import Service
from .finding import rel_time
from .rule import Context


def stats(gaps_s: np.ndarray) -> dict:
    """count, min, median, mean, p99, max and jitter (standard deviation), in ms."""
    g = gaps_s * 1000.0
    if g.size == 0:
        return {"count": 0}
    return {
        "count": int(g.size),
        "min": float(g.min()),
        "median": float(np.median(g)),
        "mean": float(g.mean()),
        "p99": float(np.percentile(g, 99)),
        "max": float(g.max()),
        "jitter": float(g.std()),
    }


class Timing:
    def __init__(self) -> None:
        self.gaps: dict[str, dict[int, list[np.ndarray]]] = {"heartbeat": {}, "pdo": {}, "sync": {}}
        self.gap_t: dict[str, dict[int, list[np.ndarray]]] = {
            "heartbeat": {},
            "pdo": {},
            "sync": {},
        }
        self.count: dict[str, Counter] = {
            "heartbeat": Counter(),
            "pdo": Counter(),
            "sync": Counter(),
        }
        self.span: dict[str, dict[int, list[float]]] = {"heartbeat": {}, "pdo": {}, "sync": {}}
        self.emcy: Counter = Counter()
        self.bootups: Counter = Counter()
        self.sdo_latency: dict[int | None, list[float]] = {}
        self.sdo_results: Counter = Counter()
        self.error_frames = 0

    def update(self, ctx: Context) -> None:
        b = ctx.batch
        if len(b) == 0:
            return
        for name in ("heartbeat", "pdo", "sync"):
            g = ctx.gaps(name)
            gap = g.gap
            for key, sl in g.groups():
                self.count[name][key] += sl.stop - sl.start
                sp = self.span[name].setdefault(key, [float(g.t[sl.start]), 0.0])
                sp[1] = float(g.t[sl.stop - 1])
                gg = gap[sl]
                ok = ~np.isnan(gg)
                self.gaps[name].setdefault(key, []).append(gg[ok])
                self.gap_t[name].setdefault(key, []).append(g.prev[sl][ok])
        emcy = b.node[b.service == Service.EMCY]
        if emcy.size:
            self.emcy.update(emcy.tolist())
        boot = b.node[b.service == Service.BOOTUP]
        if boot.size:
            self.bootups.update(boot.tolist())
        self.error_frames += int(np.count_nonzero(b.service == Service.ERROR_FRAME))
        for _row, rec in b.records:
            if rec.get("kind") == "sdo":
                self.sdo_results[rec.get("result")] += 1
                if rec.get("latency_ms") is not None:
                    self.sdo_latency.setdefault(rec.get("node"), []).append(
                        float(rec["latency_ms"])
                    )

    def all_gaps(self, name: str, key: int) -> tuple[np.ndarray, np.ndarray]:
        """(gap start times, gaps in s) of one node / COB-ID over the whole log."""
        parts = self.gaps[name].get(key)
        if not parts:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(self.gap_t[name][key]), np.concatenate(parts)

    def rate_hz(self, name: str, key: int) -> float | None:
        n = self.count[name].get(key, 0)
        sp = self.span[name].get(key)
        if n < 2 or not sp or sp[1] <= sp[0]:
            return None
        return (n - 1) / (sp[1] - sp[0])

    def report(self, nmt=None) -> dict:
        out: dict = {"heartbeat": {}, "pdo": {}, "sync": None}
        for node in sorted(self.gaps["heartbeat"]):
            out["heartbeat"][node] = stats(self.all_gaps("heartbeat", node)[1])
        for cob in sorted(self.gaps["pdo"]):
            s = stats(self.all_gaps("pdo", cob)[1])
            s["rate_hz"] = self.rate_hz("pdo", cob)
            out["pdo"][cob] = s
        if self.gaps["sync"]:
            out["sync"] = stats(self.all_gaps("sync", 0)[1])
        out["sdo_latency"] = {n: stats(np.asarray(v) / 1000.0) for n, v in self.sdo_latency.items()}
        out["sdo_results"] = dict(self.sdo_results)
        out["emcy"] = dict(self.emcy)
        out["bootups"] = dict(self.bootups)
        out["error_frames"] = self.error_frames
        if nmt is not None:
            out["nmt"] = nmt.timeline()
        return out

    def lines(self, nmt=None, t0: float | None = None) -> list[str]:
        r = self.report(nmt)

        def fmt(s: dict) -> str:
            if not s.get("count"):
                return "no gaps"
            return (
                f"n={s['count']} min {s['min']:.2f} median {s['median']:.2f} mean {s['mean']:.2f} "
                f"p99 {s['p99']:.2f} max {s['max']:.2f} jitter {s['jitter']:.2f} ms"
            )

        out = []
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
        if r["sdo_latency"]:
            out.append("SDO latency per node:")
            out += [
                f"  node {n}: {fmt(s)}"
                for n, s in sorted(r["sdo_latency"].items(), key=lambda x: str(x[0]))
            ]
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
            steps = ", ".join(f"{rel_time(t, t0)} {s} ({src})" for t, s, src in changes[:12])
            more = f", ... {len(changes) - 12} more" if len(changes) > 12 else ""
            out.append(f"NMT state node {node}: {steps}{more}")
        return out
