"""`live --record FILE` as a sink: the raw frames as they arrived, in the file's format."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from cananalyze.pipeline.sink import Sink

FLUSH_SECONDS = 1.0  # a killed session (kill -9) loses at most this much of its recording


class RecordSink(Sink):
    """Every frame of every batch (a recording is never filtered), through `FrameRecorder`.

    The recording is kept when the run ends in any way, an interface failure included:
    it is what the bus said, however far it got. What it holds is put on the file every
    `FLUSH_SECONDS`, so a session killed without a chance to close (SIGKILL, OOM killer)
    leaves a readable file with every frame up to the last second.
    """

    def __init__(self, path: str | Path) -> None:
        from cananalyze.formats.record import FrameRecorder

        self.path = path
        self.dest = str(path) if path is not None else None
        self._recorder_type = FrameRecorder
        self.recorder = None
        FrameRecorder.check_suffix(path)  # a wrong suffix fails before the bus opens

    def open(self, run) -> None:
        super().open(run)
        self.recorder = self._recorder_type(self.path)
        self._flushed = time.monotonic()

    def write(self, batch) -> None:
        """The decoded batch: an .mcap recording keeps the service and node the decoder
        gave each frame (remaps included), as export writes them."""
        self.recorder.write(batch)
        self.tick(time.monotonic())

    def tick(self, now: float) -> None:
        """Put what was recorded on the file once a second, also on a quiet bus."""
        if self.recorder is not None and now - self._flushed >= FLUSH_SECONDS:
            self.recorder.flush()
            self._flushed = now

    def close(self) -> None:
        self._finish()

    def abort(self) -> None:
        self._finish()

    def _finish(self) -> None:
        if self.recorder is not None:
            self.recorder.close()
            print(f"recorded {self.recorder.frames} frames to {self.path}", file=sys.stderr)
            self.recorder = None
