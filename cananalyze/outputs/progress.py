"""A progress bar for long runs on a terminal: percent and time left from the file position.

Drawn on stderr by rich and removed when the run ends; a source whose size is
unknown (stdin, a pipe, a live bus) shows the frame count only.
"""

from __future__ import annotations

from typing import TextIO

from cananalyze.pipeline.sink import Sink


class ProgressSink(Sink):
    def __init__(self, stream: TextIO, label: str = "decoding") -> None:
        self.stream = stream
        self.label = label
        self._bar = None

    def open(self, run) -> None:
        super().open(run)
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            Progress,
            TaskProgressColumn,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        fraction = getattr(run.source, "fraction", None)
        self._fraction = fraction if fraction is not None and fraction() is not None else None
        columns = [TextColumn("{task.description}"), TextColumn("{task.fields[frames]:,} frames")]
        if self._fraction is not None:
            columns[1:1] = [BarColumn(), TaskProgressColumn()]
            columns.append(TimeRemainingColumn())
        else:
            columns.append(TimeElapsedColumn())
        self._bar = Progress(*columns, console=Console(file=self.stream), transient=True)
        self._task = self._bar.add_task(
            self.label, total=1000 if self._fraction is not None else None, frames=0
        )
        self._bar.start()

    def write(self, batch) -> None:
        done = self._fraction() if self._fraction is not None else None
        self._bar.update(
            self._task,
            completed=None if done is None else done * 1000,
            frames=self.run.frames,
        )

    def close(self) -> None:
        self._stop()

    def abort(self) -> None:
        self._stop()

    def _stop(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
