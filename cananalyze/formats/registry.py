"""The table of log formats: how to recognise each from its first bytes, its reader, and
its writer where we write it.

One module per format registers one LogFormat here (python-can's `can/io/<format>.py`
and its LogReader/Logger facades, but choosing by content first and by suffix only as a
tie-breaker).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Protocol

from cananalyze.core.errors import ProblemLog
from cananalyze.core.frames import FrameBatch

DEFAULT_BATCH = 262144


@dataclass
class ReadContext:
    """What a reader needs besides the stream, and what it reports back."""

    source: str  # file name for messages ("-" for stdin)
    problems: ProblemLog
    batch_size: int = DEFAULT_BATCH
    # filled in by the reader:
    format: str = ""
    absolute_time: bool = False  # timestamps are Unix epoch seconds
    start_time: float | None = None  # epoch of the log's start, if the header says
    frames: int = 0  # frames yielded so far
    extras: dict = field(default_factory=dict)


Reader = Callable[[BinaryIO, ReadContext], Iterator[FrameBatch]]


class FrameWriter(Protocol):
    """A log file being written: batches appended, `flush` puts what was written on the
    file (a process killed after it leaves those frames readable), `close` finishes it."""

    def write(self, batch: FrameBatch) -> None: ...
    def flush(self) -> None: ...
    def close(self) -> None: ...


@dataclass(frozen=True)
class LogFormat:
    name: str  # "candump", "asc", "blf", "trc", ...
    description: str
    sniff: Callable[[bytes], bool]  # given the head: 64 KiB, more when none claims that
    read: Reader
    suffixes: tuple[str, ...] = ()
    priority: int = 50  # lower sniffs first; one format a number, so the order is this data
    # a text format's CR-only line ends are made newlines; a binary format's bytes are never
    # touched (0x0D is just a byte in a pcap's microseconds or a BLF's payload)
    text: bool = True
    # where we write the format: the suffix it is written with and the writer's factory
    write_suffix: str = ""
    writer: Callable[[Path], FrameWriter] | None = None


FORMATS: list[LogFormat] = []


def register(fmt: LogFormat) -> LogFormat:
    """Called once by each format module as it is imported (the source facade imports
    every module of this package): a new format is its module and nothing else."""
    taken = {f.priority: f.name for f in FORMATS if f.name != fmt.name}
    if fmt.priority in taken:
        raise ValueError(f"{fmt.name}: priority {fmt.priority} is {taken[fmt.priority]}'s")
    FORMATS[:] = [f for f in FORMATS if f.name != fmt.name]
    FORMATS.append(fmt)
    FORMATS.sort(key=lambda f: f.priority)
    return fmt
