"""RerunLive: a live session's timelines streamed to rerun while it sniffs.

Same entities and blueprint as the offline export (`rerun_out`). Decoded batches
are gathered for `every` seconds, turned into columns by the same Collector the
offline Capture uses, and sent with `send_columns`: one call per series per flush,
never one log call per frame. Bus load is summed into 0.1 s windows aligned to the
clock, a window sent once it is complete. The .rrd sink is flushed after every
send, so a file cut short holds everything up to the last flush; `close()` writes
the footer, which is what Ctrl-C / SIGTERM reach through the live command's cleanup.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ...capture import Collector
from ...errors import ProblemLog, UsageError
from ...records import DecodedBatch
from ..busload import frame_bits
from .send import LOAD_WINDOW, blueprint_for, is_absolute, send_header, send_load, send_parts


class RerunLive:
    """Send DecodedBatches to an .rrd file and/or a spawned viewer, in batches."""

    def __init__(
        self,
        rrd: str | Path | None = None,
        spawn: bool = False,
        bitrate: int | None = None,
        name: str = "live",
        network: str = "",
        every: float = 0.5,
    ) -> None:
        import rerun as rr

        if not rrd and not spawn:
            raise ValueError("RerunLive needs an .rrd file, a viewer, or both")
        if rrd:
            from ..atomic import check_writable

            check_writable(rrd)
        self.bitrate = bitrate
        self.every = every
        self.counts: dict[str, int] = {}
        self._named: set[str] = set()
        self._layout: tuple[set, set] = (set(), set())  # PDOs and NMT lanes in the blueprint
        self._collector = Collector(name, records=False)
        self._pending = 0
        self._last_send = time.monotonic()
        self._absolute: bool | None = None
        self._load_bin: int | None = None  # window index of the incomplete bus load window
        self._load_bits = 0.0
        self.rec = rr.RecordingStream("cananalyze", send_properties=True)
        sinks = []
        if spawn:
            rr.spawn(connect=False, recording=self.rec)
            sinks.append(rr.GrpcSink())
        if rrd:
            sinks.append(rr.FileSink(str(rrd)))
        try:
            self.rec.set_sinks(*sinks, default_blueprint=blueprint_for(set(), set()))
        except Exception as exc:  # noqa: BLE001 - rerun raises its own types for sink failures
            raise UsageError(f"rerun: cannot open {rrd or 'the viewer'}: {exc}") from None
        self.rec.send_recording_name(name)
        send_header(self.rec, name, network)

    def add(self, batch: DecodedBatch) -> None:
        """Keep a decoded batch; send what was kept once `every` seconds have passed."""
        if len(batch) or batch.records or batch.signals or len(batch.findings):
            self._collector.add(batch)
            self._pending += 1
        if self._pending and time.monotonic() - self._last_send >= self.every:
            self.send()

    def flush_due(self) -> None:
        """Send what was kept once `every` seconds have passed (a quiet bus included)."""
        if self._pending and time.monotonic() - self._last_send >= self.every:
            self.send()

    def send(self, final: bool = False) -> None:
        """Send everything kept so far (and, when final, the last partial load window)."""
        col = self._collector
        cap = col.capture(ProblemLog())
        self._collector = Collector(col.source, col.event_state, records=False)
        self._pending = 0
        self._last_send = time.monotonic()
        t = cap.batch.t
        if self._absolute is None and t.size:
            self._absolute = is_absolute(t)
        absolute = bool(self._absolute)
        pdos = self._layout[0] | {(s.node, s.pdo, s.cob_id) for s in cap.series}
        lanes = self._layout[1] | {e.node for e in cap.state_changes}
        if (pdos, lanes) != self._layout:
            self._layout = (pdos, lanes)
            self.rec.send_blueprint(blueprint_for(pdos, lanes), make_active=True, make_default=True)
        send_parts(cap, self.rec, absolute, self.counts, self._named)
        self._send_load(cap, absolute, final)
        self.rec.flush()

    def _send_load(self, cap, absolute: bool, final: bool) -> None:
        fb = cap.batch
        starts: list[float] = []
        values: list[float] = []
        if len(fb):
            idx = np.floor(fb.t / LOAD_WINDOW).astype(np.int64)
            bits = frame_bits(fb.flags, fb.dlc).astype(np.float64)
            if self._load_bin is not None:  # the window left open by the last flush
                idx = np.concatenate([[self._load_bin], idx])
                bits = np.concatenate([[self._load_bits], bits])
            first = int(idx.min())
            sums = np.bincount(idx - first, weights=bits)
            last = first + sums.size - 1
            starts = ((first + np.arange(sums.size - 1)) * LOAD_WINDOW).tolist()
            values = (sums[:-1] / LOAD_WINDOW).tolist()
            self._load_bin, self._load_bits = last, float(sums[-1])
        if final and self._load_bin is not None:
            starts.append(self._load_bin * LOAD_WINDOW)
            values.append(self._load_bits / LOAD_WINDOW)
            self._load_bin = None
        if values:
            load = np.array(values)
            if self.bitrate:
                load = load / self.bitrate * 100.0
            send_load(
                self.rec, np.array(starts), load, absolute, self.bitrate, self.counts, self._named
            )

    def close(self) -> None:
        """Send the rest and finish the recording (the .rrd footer); idempotent."""
        if self.rec is None:
            return
        try:
            self.send(final=True)
        finally:
            self.rec.flush()
            self.rec.disconnect()
            self.rec = None
