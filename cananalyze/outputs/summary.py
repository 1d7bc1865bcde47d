"""`decode --summary`: frames per service and node, duration, bus load. Columnar counts.

Bus load is a lower bound (nominal bits, no stuff bits): see cananalyze.busload.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass, field

import numpy as np

from ..busload import frame_bits
from ..decoded import DecodedBatch
from ..frames import FLAG_EXT
from ..protocol.services import SERVICE_NAMES, Service

N_SVC = len(SERVICE_NAMES)


@dataclass
class Summary:
    frames: int = 0
    t_first: float | None = None
    t_last: float | None = None
    by_service: np.ndarray = field(default_factory=lambda: np.zeros(N_SVC, np.int64))
    by_node_service: np.ndarray = field(default_factory=lambda: np.zeros((128, N_SVC), np.int64))
    bits: int = 0
    ids_seen: set = field(default_factory=set)
    skipped: int = 0
    # SDO transactions per node: result counts and latencies (8 bytes each, not the
    # records: a 50M-frame log has millions, and memory must stay flat in log length)
    sdo_results: dict = field(default_factory=dict)  # node -> {result: count}
    sdo_latency: dict = field(default_factory=dict)  # node -> array('d') of ms

    def add(self, batch: DecodedBatch) -> None:
        n = len(batch)
        for _row, rec in batch.records:
            if rec.get("kind") == "sdo":
                node = rec.get("node")
                results = self.sdo_results.setdefault(node, {})
                results[rec.get("result")] = results.get(rec.get("result"), 0) + 1
                lat = self.sdo_latency.setdefault(node, array("d"))
                if rec.get("latency_ms") is not None:
                    lat.append(rec["latency_ms"])
        if n == 0:
            return
        fb = batch.frames
        self.frames += n
        t = fb.t
        self.t_first = float(t[0]) if self.t_first is None else min(self.t_first, float(t[0]))
        self.t_last = float(t[-1]) if self.t_last is None else max(self.t_last, float(t[-1]))
        self.by_service += np.bincount(batch.service, minlength=N_SVC)
        has = batch.node >= 0
        key = batch.node[has].astype(np.int64) * N_SVC + batch.service[has]
        self.by_node_service += np.bincount(key, minlength=128 * N_SVC).reshape(128, N_SVC)
        self.bits += int(frame_bits(fb.flags, fb.dlc).sum())
        if len(self.ids_seen) < 4096:
            self.ids_seen.update(np.unique(fb.can_id[(fb.flags & FLAG_EXT) == 0]).tolist())

    @property
    def duration(self) -> float:
        if self.t_first is None or self.t_last is None:
            return 0.0
        return self.t_last - self.t_first

    def canopen_verdict(self) -> str | None:
        """A sentence when the traffic does not look like CANopen, else None."""
        if self.frames == 0:
            return "The log holds no frames."
        other = int(self.by_service[Service.OTHER]) + int(self.by_service[Service.ERROR_FRAME])
        markers = sum(
            int(self.by_service[s])
            for s in (Service.HEARTBEAT, Service.BOOTUP, Service.NMT, Service.GUARD_REQUEST)
        )
        if other / self.frames > 0.5:
            return (
                f"This does not look like CANopen: {other} of {self.frames} frames use identifiers "
                "outside the predefined connection set."
            )
        if markers == 0 and self.frames > 200:
            return (
                "This may not be CANopen: no heartbeat, boot-up, guarding or NMT frame in "
                f"{self.frames} frames; identifiers merely fall into CANopen ranges."
            )
        return None

    def lines(self, bitrate: int | None = None, problems: int = 0) -> list[str]:
        out = [f"frames: {self.frames}", f"duration: {self.duration:.6f} s"]
        if bitrate and self.duration > 0:
            load = self.bits / (bitrate * self.duration) * 100
            out.append(f"bus load: {load:.1f} % at {bitrate} bit/s (nominal bits, no stuff bits)")
        elif bitrate:
            out.append("bus load: n/a (no duration)")
        if problems:
            out.append(f"skipped input lines/records: {problems}")
        out.append("frames per service:")
        for i, name in enumerate(SERVICE_NAMES):
            if self.by_service[i]:
                out.append(f"  {name:<15} {int(self.by_service[i]):>10}")
        nodes = np.flatnonzero(self.by_node_service.sum(axis=1))
        if nodes.size:
            out.append("frames per node:")
            for n in nodes:
                parts = [
                    f"{SERVICE_NAMES[s]}={int(c)}"
                    for s, c in enumerate(self.by_node_service[n])
                    if c
                ]
                out.append(
                    f"  node {int(n):>3}: {int(self.by_node_service[n].sum()):>8}  "
                    + " ".join(parts)
                )
        if self.sdo_results:
            out.append("SDO transactions per node:")
            for node in sorted(self.sdo_results, key=lambda x: (x is None, x)):
                results = self.sdo_results[node]
                lat = self.sdo_latency[node]
                text = (
                    f"  node {node}: {sum(results.values())} ("
                    + ", ".join(f"{k} {v}" for k, v in sorted(results.items()))
                    + ")"
                )
                if lat:
                    text += (
                        f"; latency ms min {min(lat):.2f} median {float(np.median(lat)):.2f} "
                        f"max {max(lat):.2f}"
                    )
                out.append(text)
        verdict = self.canopen_verdict()
        if verdict:
            out.append(verdict)
        return out


def device_lines(model, summary: Summary | None = None) -> list[str]:
    """Each node seen or declared: its device and how it was identified."""
    known = dict(getattr(model, "nodes", {}))
    seen_nodes = set(known)
    if summary is not None:
        seen_nodes |= {int(n) for n in np.flatnonzero(summary.by_node_service.sum(axis=1))}
    out = []
    for node in sorted(seen_nodes):
        cfg = known.get(node)
        if cfg is None:
            out.append(f"  node {node:>3}: unknown device (no identity read in the log; give --device or --eds)")
            continue
        name = cfg.profile.name if cfg.profile is not None else "unknown device"
        seen = ", ".join(
            f"{k} 0x{v:X}" if isinstance(v, int) else f"{k} {v!r}" for k, v in sorted(cfg.identity.items())
        )
        line = f"  node {node:>3}: {name} (identified by {cfg.identified_by})"
        out.append(line + (f"; seen {seen}" if seen else ""))
    return ["devices:", *out] if out else []

