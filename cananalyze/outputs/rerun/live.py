"""RerunLive: a live session's timelines streamed to rerun while it sniffs.

Same entities and blueprint as the offline export (`rerun_out`). Decoded batches
are gathered for `every` seconds, turned into columns by the same Collector the
offline Capture uses, and sent with `send_columns`: one call per series per flush,
never one log call per frame. Bus load is summed into 0.1 s windows aligned to the
clock, a window sent once it is complete; per bus once the session has several
(`live -c can0,can1`: /can0/bus/load, /can1/bus/load, as the offline export). The .rrd sink is flushed after every
send, so a file cut short holds everything up to the last flush; `close()` writes
the footer, which is what Ctrl-C / SIGTERM reach through the live command's cleanup.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from cananalyze.core.errors import ProblemLog, UsageError
from cananalyze.core.records import DecodedBatch
from cananalyze.outputs.capture import Collector
from cananalyze.outputs.rerun.send import (
    LOAD_WINDOW,
    Layout,
    is_absolute,
    send_header,
    send_load,
    send_parts,
)
from cananalyze.protocol.busload import bits_by_channel


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
            from cananalyze.core.atomic import check_writable

            check_writable(rrd)
        self.bitrate = bitrate
        self.every = every
        self.counts: dict[str, int] = {}
        self._named: set[str] = set()
        self._layout = Layout()  # what the blueprint sent last names
        self._collector = Collector(name, records=False)
        self._pending = 0
        self._last_send = time.monotonic()
        self._absolute: bool | None = None
        # channel name -> (window index, bits) of its incomplete bus load window
        self._load_open: dict[str, tuple[int, float]] = {}
        self.rec = rr.RecordingStream("cananalyze", send_properties=True)
        sinks = []
        if spawn:
            rr.spawn(connect=False, recording=self.rec)
            sinks.append(rr.GrpcSink())
        if rrd:
            sinks.append(rr.FileSink(str(rrd)))
        try:
            self.rec.set_sinks(*sinks, default_blueprint=self._layout.blueprint())
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
        grew = self._layout.add(cap)
        send_parts(cap, self.rec, absolute, self.counts, self._named)
        grew |= self._send_load(cap, absolute, final)
        if grew:
            self.rec.send_blueprint(self._layout.blueprint(), make_active=True, make_default=True)
        self.rec.flush()

    def _send_load(self, cap, absolute: bool, final: bool) -> bool:
        """Each bus's complete windows (and, when final, its open one); True when a bus
        load entity is new to the layout."""
        fb = cap.batch
        parts = bits_by_channel(fb)
        several = len(fb.channels) > 1 or len(self._load_open) > 1
        grew = False
        for label in sorted(set(parts) | set(self._load_open)):
            t, b = parts.get(label, (np.zeros(0), np.zeros(0)))
            starts, values = self._windows(label, t, b, final)
            if values.size:
                if self.bitrate:
                    values = values / self.bitrate * 100.0
                path = send_load(
                    self.rec,
                    label if several else None,
                    starts,
                    values,
                    absolute,
                    self.bitrate,
                    self.counts,
                    self._named,
                )
                grew |= path not in self._layout.loads
                self._layout.loads.add(path)
        return grew

    def _windows(self, label: str, t: np.ndarray, bits: np.ndarray, final: bool):
        """(window starts, bits/s) of one bus's windows this send completes; the last stays
        open for the next send unless final."""
        starts: list[float] = []
        values: list[float] = []
        idx = np.floor(t / LOAD_WINDOW).astype(np.int64)
        if label in self._load_open:  # the window left open by the last flush
            at, open_bits = self._load_open.pop(label)
            idx = np.concatenate([[at], idx])
            bits = np.concatenate([[open_bits], bits])
        if idx.size:
            first = int(idx.min())
            sums = np.bincount(idx - first, weights=bits)
            starts = ((first + np.arange(sums.size - 1)) * LOAD_WINDOW).tolist()
            values = (sums[:-1] / LOAD_WINDOW).tolist()
            last = (first + sums.size - 1, float(sums[-1]))
            if final:
                starts.append(last[0] * LOAD_WINDOW)
                values.append(last[1] / LOAD_WINDOW)
            else:
                self._load_open[label] = last
        return np.array(starts), np.array(values)

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
