"""Sources: a log file, stdin, a live bus or frames in memory, each yielding FrameBatches."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Protocol

from cananalyze.core.errors import ProblemLog
from cananalyze.core.frames import FrameBatch
from cananalyze.pipeline.options import Options


class Source(Protocol):
    """Where frames come from: a log file, stdin or a live bus."""

    path: str
    problems: ProblemLog

    def batches(self) -> Iterator[FrameBatch]: ...


class MemorySource:
    """Frames already in memory (tests, the simulator, pytest assertions) as a Source."""

    def __init__(self, batches: FrameBatch | Iterable[FrameBatch], path: str = "<frames>") -> None:
        self._batches = [batches] if isinstance(batches, FrameBatch) else list(batches)
        self.path = path
        self.problems = ProblemLog()

    def batches(self) -> Iterator[FrameBatch]:
        yield from self._batches


def open_source(log: str | Path | object, opts: Options | None = None) -> Source:
    """A log path (or "-" for stdin) opened for batch reading, or a python-can bus.

    Raises InputError with a one-line reason for a file it cannot read.
    """
    opts = opts or Options()
    if isinstance(log, (str, Path)):
        from cananalyze.formats.source import open_log

        return open_log(
            log, strict=opts.strict, fmt=opts.input_format, storage_options=opts.storage_options
        )
    if isinstance(log, FrameBatch):
        return MemorySource(log)
    from cananalyze.formats.live import LiveSource

    return LiveSource(log)
