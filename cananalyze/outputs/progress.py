"""The progress bar on a terminal: one place for when it shows and when it goes.

A bar is drawn on stderr by rich only once the work has taken `progress_delay()`
seconds (1 s; a short log never shows one), and it is erased, its line cleared,
before the first line of results reaches the terminal: `ProgressSink` is the first
sink of a run, so its `finish` (or `abort`) runs before any other sink prints its
findings or summary; the fleet clears it before its table. `decode` without `-o`
shows none (its lines go to the terminal from the first frame), nor does a pipe,
nor `--quiet`.

`CANANALYZE_PROGRESS_DELAY=SECONDS` in the environment sets the delay (read only
here, by `progress_delay`): 0 draws the bar at once (the terminal tests use it, so
they do not depend on how fast the machine is), a large value never draws it.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable, Mapping
from typing import TextIO

from cananalyze.pipeline.sink import Sink

DELAY_ENV = "CANANALYZE_PROGRESS_DELAY"
DEFAULT_DELAY = 1.0  # seconds of work before a bar is worth its line


def progress_delay(environ: Mapping[str, str] | None = None) -> float:
    """Seconds before a bar appears: `CANANALYZE_PROGRESS_DELAY` when it is a number
    >= 0, else `DEFAULT_DELAY` (a typo there must not stop the run)."""
    env = os.environ if environ is None else environ
    text = env.get(DELAY_ENV, "").strip()
    try:
        value = float(text)
    except ValueError:
        return DEFAULT_DELAY
    return value if math.isfinite(value) and value >= 0 else DEFAULT_DELAY


class DelayedBar:
    """A rich progress bar that starts `delay` seconds after it is made (at once for 0)
    and whose `clear()` erases it for good: a bar started late never overwrites results.

    `make()` builds the rich `Progress` (columns, console) and `add(progress)` its task:
    both only when the bar is due, so a short run imports and draws nothing. `update`
    keeps the latest values for a bar not drawn yet.
    """

    def __init__(
        self,
        make: Callable[[], object],
        add: Callable[[object], object],
        delay: float | None = None,
    ) -> None:
        self._make = make
        self._add = add
        self._values: dict = {}
        self._lock = threading.Lock()
        self._bar = None
        self._task = None
        self._cleared = False
        self._drawn = False
        self._timer: threading.Timer | None = None
        self.delay = progress_delay() if delay is None else delay
        if self.delay <= 0:
            self._start()
        else:  # a timer: the bar appears on time even when updates are far apart
            self._timer = threading.Timer(self.delay, self._start)
            self._timer.daemon = True
            self._timer.start()

    @property
    def drawn(self) -> bool:
        """Whether the bar was ever put on the terminal."""
        return self._drawn

    def _start(self) -> None:
        with self._lock:
            if self._cleared or self._bar is not None:
                return
            bar = self._make()
            self._task = self._add(bar)
            if self._values:
                bar.update(self._task, **self._values)
            bar.start()
            self._bar = bar
            self._drawn = True

    def update(self, **values) -> None:
        """The bar's task fields now (`completed`, `advance`, columns' fields)."""
        with self._lock:
            if self._cleared:
                return
            if self._bar is None:
                advance = values.pop("advance", None)
                if advance is not None:
                    values["completed"] = self._values.get("completed", 0) + advance
                self._values.update(values)
            else:
                self._bar.update(self._task, **values)

    def clear(self) -> None:
        """Erase the bar's line (rich's transient stop) and never draw it again."""
        with self._lock:
            self._cleared = True
            if self._timer is not None:
                self._timer.cancel()
            bar, self._bar = self._bar, None
            if bar is not None:
                bar.stop()


def terminal_bar(stream: TextIO, columns: Callable[[], list], **fields) -> Callable[[], object]:
    """`make` for a DelayedBar: a transient rich Progress of `columns()` on `stream`."""

    def make():
        from rich.console import Console
        from rich.progress import Progress

        return Progress(*columns(), console=Console(file=stream), transient=True)

    return make


class ProgressSink(Sink):
    """Percent and time left from the file position (the frame count alone for a source
    of unknown size: stdin, a pipe, a live bus). Put first among a run's sinks, so that
    it is cleared before the others print (`cli.common.run_with_progress` does)."""

    def __init__(self, stream: TextIO, label: str = "decoding", delay: float | None = None) -> None:
        self.stream = stream
        self.label = label
        self.delay = delay
        self.bar: DelayedBar | None = None

    def open(self, run) -> None:
        super().open(run)
        fraction = getattr(run.source, "fraction", None)
        self._fraction = fraction if fraction is not None and fraction() is not None else None
        sized = self._fraction is not None

        def columns() -> list:
            from rich.progress import (
                BarColumn,
                TaskProgressColumn,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            cols = [TextColumn("{task.description}"), TextColumn("{task.fields[frames]:,} frames")]
            if sized:
                cols[1:1] = [BarColumn(), TaskProgressColumn()]
                cols.append(TimeRemainingColumn())
            else:
                cols.append(TimeElapsedColumn())
            return cols

        total = 1000 if sized else None
        self.bar = DelayedBar(
            terminal_bar(self.stream, columns),
            lambda bar: bar.add_task(self.label, total=total, frames=0),
            self.delay,
        )

    def write(self, batch) -> None:
        done = self._fraction() if self._fraction is not None else None
        if self.bar is not None:
            self.bar.update(completed=None if done is None else done * 1000, frames=self.run.frames)

    def finish(self) -> None:
        """Cleared before the other sinks' `finish` prints the results."""
        self._stop()

    def close(self) -> None:
        self._stop()

    def abort(self) -> None:
        self._stop()

    def _stop(self) -> None:
        if self.bar is not None:
            self.bar.clear()
