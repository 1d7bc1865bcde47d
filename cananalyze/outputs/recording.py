"""`live --record FILE` as a sink: the raw frames as they arrived, in the file's format."""

from __future__ import annotations

import sys
from pathlib import Path

from cananalyze.pipeline.sink import Sink


class RecordSink(Sink):
    """Every frame of every batch (a recording is never filtered), through `FrameRecorder`.

    The recording is kept when the run ends in any way, an interface failure included:
    it is what the bus said, however far it got.
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

    def write(self, batch) -> None:
        """The decoded batch: an .mcap recording keeps the service and node the decoder
        gave each frame (remaps included), as export writes them."""
        self.recorder.write(batch)

    def close(self) -> None:
        self._finish()

    def abort(self) -> None:
        self._finish()

    def _finish(self) -> None:
        if self.recorder is not None:
            self.recorder.close()
            print(f"recorded {self.recorder.frames} frames to {self.path}", file=sys.stderr)
            self.recorder = None
