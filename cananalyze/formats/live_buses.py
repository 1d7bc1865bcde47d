"""Several buses at once: one LiveSource (reader thread and ring) per bus, merged in time.

`live -c can0,can1` (or repeated -i/-c pairs) opens one python-can bus per channel.
Each keeps its own reader thread, so a busy bus never waits for a quiet one; the
consumer takes what every ring holds each interval and hands the decoder one
FrameBatch in time order, every frame keeping its channel (the batch's channel table
is the union of the buses' names, in the order given).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator

import numpy as np

from cananalyze.core.errors import ProblemLog
from cananalyze.core.frames import FrameBatch, concat
from cananalyze.formats.live import LiveError, LiveSource


class LiveBuses(LiveSource):
    """A LiveSource over several LiveSources (the pipeline treats it as one live bus)."""

    def __init__(self, sources: list[LiveSource], interval: float = 0.05) -> None:
        # no ring of its own: the parts read, this merges (LiveSource.__init__ not called)
        self.parts = list(sources)
        self.interval = interval
        self._stop = threading.Event()
        self._names: list[str] = []
        self._lines = 0
        self.error: str | None = None
        self.path = "live"
        self.problems = ProblemLog()

    @property
    def received(self) -> int:
        return sum(p.received for p in self.parts)

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self._names)

    def start(self) -> LiveBuses:
        for p in self.parts:
            p.start()
            for name in p.channels:  # the buses' names in the order given
                self._code(name)
        return self

    def stop(self) -> None:
        self._stop.set()
        for p in self.parts:
            p.stop()

    @property
    def stopping(self) -> bool:
        return self._stop.is_set() or any(p.stopping for p in self.parts)

    def take(self) -> FrameBatch:
        """Everything every bus received since the last take, in time order."""
        parts = []
        for p in self.parts:
            fb = p.take()
            if not len(fb):
                continue
            codes = np.array([self._code(fb.channel_label(c)) for c in range(len(fb.channels))])
            fb.channel = codes[fb.channel].astype(np.uint16) if codes.size else fb.channel
            parts.append(fb)
        names = tuple(self._names)
        if not parts:
            return FrameBatch.empty(names)
        for fb in parts:
            fb.channels = names
        out = concat(parts)
        if len(parts) > 1:
            out = out.take(np.argsort(out.t, kind="stable"))
        out.line[:] = np.arange(self._lines + 1, self._lines + len(out) + 1)
        self._lines += len(out)
        return out

    def _code(self, name: str) -> int:
        if name not in self._names:
            self._names.append(name)
        return self._names.index(name)

    def batches(self) -> Iterator[FrameBatch]:
        """Merged batches until stop() or until any bus fails (then LiveError)."""
        self.start()
        try:
            while True:
                stopped = self.stopping
                self._stop.wait(self.interval)
                yield self.take()
                if stopped:
                    break
            for p in self.parts:
                p.close()  # joins the reader: what it read last is in its ring
            rest = self.take()
            if len(rest):
                yield rest
        finally:
            self.close()
        failed = [p.error for p in self.parts if p.error]
        if failed:
            raise LiveError(f"interface error: {failed[0]}")

    def close(self) -> None:
        self.stop()
        for p in self.parts:
            p.close()
