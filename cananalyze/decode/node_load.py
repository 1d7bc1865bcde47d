"""Bus load per node and the longest burst, followed batch by batch: `decode --summary`,
`check --timing`, the report and the nodes table (`NodeTally`) take the same figures from
this one computation (protocol/busload's bits). The longest burst is the decoder's
(decode/commissioning follows it once, for the events table too): read here from the
batch that carries it.

A node's load is the nominal bits of the frames it sent itself (decode/senders: its
heartbeat, TPDOs, EMCY, SDO responses, guard answers, boot-up) over the log's duration,
in percent of the bitrate: a lower bound, as busload explains.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.decode.senders import SENT
from cananalyze.protocol.busload import bits_of_lengths, bits_per_node


def run_bitrate(run) -> int | None:
    """The run's bitrate: --bitrate, else the network file's `bitrate`, else None."""
    model = run.network
    return run.options.bitrate or (model.spec.bitrate if model is not None else None)


@dataclass
class NodeLoad:
    sent: dict = field(default_factory=dict)  # channel name -> (frames[128], bits[128])
    # channel name -> the longest burst {frames, t_start, t_end} (the decoder's event)
    bursts: dict = field(default_factory=dict)
    first: str | None = None  # the first frame's channel name (a log of one bus)
    t_first: float | None = None
    t_last: float | None = None

    @property
    def duration(self) -> float:
        if self.t_first is None or self.t_last is None:
            return 0.0
        return self.t_last - self.t_first

    def add(self, batch: DecodedBatch, present: list[int] | None = None) -> None:
        """Count a batch; `present`: its channel indexes, when the caller has them."""
        fb = batch.frames
        for c in batch.commissioning:
            if c.kind == "burst":
                self.bursts[c.bus or self.first or "can0"] = c.item
        if not len(fb):
            return
        if self.first is None:
            self.first = fb.channel_label(int(fb.channel[0]))
        # the span of the times, whatever their order (a log whose times go back)
        lo, hi = float(fb.t.min()), float(fb.t.max())
        self.t_first = lo if self.t_first is None else min(self.t_first, lo)
        self.t_last = hi if self.t_last is None else max(self.t_last, hi)
        if present is None:  # one channel: no sort of the batch's channels
            one = len(fb.channels) <= 1 or not (fb.channel != fb.channel[0]).any()
            present = [int(fb.channel[0])] if one else np.unique(fb.channel).tolist()
        if len(present) == 1:  # the batch's counts per (service, node, length), shared
            shapes = batch.sender_shapes()  # with the node tally (one pass, no gather)
            if shapes is not None:
                self._add(
                    fb.channel_label(present[0]),
                    bits_of_lengths(shapes[SENT[: len(shapes)]].sum(axis=0)),
                )
                return
        sent = np.take(SENT, batch.service)  # (half numpy's fancy indexing by uint8 codes)
        for c in present:
            mine = fb.channel == c if len(present) > 1 else slice(None)
            name = fb.channel_label(c)
            frames, nbits = bits_per_node(
                fb.flags[mine], fb.dlc[mine], batch.node[mine], sent[mine]
            )
            self._add(name, (frames, nbits))

    def _add(self, name: str, counted: tuple[np.ndarray, np.ndarray]) -> None:
        got = self.sent.get(name)
        self.sent[name] = counted if got is None else (got[0] + counted[0], got[1] + counted[1])

    def shares(self, bitrate: int | None) -> dict:
        """channel -> {node: mean bus load in percent of the frames it sent}; {} without a
        bitrate or a duration."""
        if not bitrate or self.duration <= 0:
            return {}
        per = bitrate * self.duration / 100
        return {
            name: {int(n): float(bits[n]) / per for n in np.flatnonzero(frames).tolist()}
            for name, (frames, bits) in self.sent.items()
        }

    def lines(self, bitrate: int | None, timed: bool) -> list[str]:
        """Bus load per node and the longest burst (with a bitrate and times only)."""
        if not timed:
            return []
        out = []
        loads = self.shares(bitrate)
        several = len(loads) > 1
        rows = [
            (f"{name} node {n}" if several else f"node {n}", v)
            for name, per in loads.items()
            for n, v in per.items()
        ]
        if rows:
            out.append("bus load per node (frames it sent, nominal bits):")
            out += [f"  {who:<15} {v:>9.2f} %" for who, v in rows]
        t0 = self.t_first or 0.0
        for name, rec in self.bursts.items():
            if self.duration <= 0:
                continue
            on = f" on {name}" if several else ""
            out.append(
                f"longest burst{on}: {rec['frames']} frames back to back, "
                f"{rec['t_start'] - t0:+.6f} s to {rec['t_end'] - t0:+.6f} s "
                f"({(rec['t_end'] - rec['t_start']) * 1000:.3f} ms)"
            )
        return out
