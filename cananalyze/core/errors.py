"""Input problems: what could not be read, where, and whether to go on.

Lenient by default: a reader records a Problem and skips the line or record;
with strict=True the first problem raises InputError, which the CLI turns into
a one-line message and exit code 2. Never a traceback for bad input.
"""

from __future__ import annotations

from dataclasses import dataclass, field


class CananalyzeError(Exception):
    """Base of errors that the CLI reports in one line (exit 2)."""


class InputError(CananalyzeError):
    """A log, network or rules file that cannot be read as asked."""


class UsageError(CananalyzeError):
    """Bad command-line arguments or option values."""


def read_bounded(path, limit: int, what: str, too_big: str = "") -> bytes:
    """A whole configuration or device file, read only up to `limit` bytes: a file (or
    /dev/zero) larger than that is refused in one line, never read whole. `what` names
    it in the messages ("network file"); `too_big`, the refusal's words, if not
    "<what> is larger than N MiB"."""
    try:
        with open(path, "rb") as f:
            data = f.read(limit + 1)
    except OSError as exc:
        raise InputError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    if len(data) > limit:
        said = too_big or f"{what} is larger than"
        raise InputError(f"{path}: {said} {limit >> 20} MiB")
    return data


@dataclass(frozen=True)
class Problem:
    source: str
    location: str  # "line 12", "record 40", "offset 1024"
    message: str

    def __str__(self) -> str:
        return f"{self.source}:{self.location}: {self.message}"


@dataclass
class ProblemLog:
    """Counts every skipped input and keeps the first few messages to show."""

    strict: bool = False
    keep: int = 20
    count: int = 0
    shown: list[Problem] = field(default_factory=list)

    # what a reader did that is no problem but changes what the user sees (loop-back
    # echoes left out): said once per run, never counted as skipped nor stopped at
    notes: list[str] = field(default_factory=list)

    def note(self, source: str, message: str) -> None:
        self.notes.append(f"{source}: {message}")

    def add(self, source: str, location: str, message: str) -> None:
        problem = Problem(source, location, message)
        if self.strict:
            raise InputError(str(problem))
        self.count += 1
        if len(self.shown) < self.keep:
            self.shown.append(problem)
