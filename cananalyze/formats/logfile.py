"""Writing frames out as logs, the format from the file's suffix: each format's writer is
registered by its module (formats/logs/: candump, in bulk; ASC and BLF by python-can's
writers, the reference implementations of those formats).

Used for samples, benchmark logs, `simulate --to` and `live --record` (formats/record.py).
"""

from __future__ import annotations

from pathlib import Path

from cananalyze.core.atomic import atomic_path
from cananalyze.core.frames import FrameBatch
from cananalyze.formats import source  # noqa: F401 - imports every format, which registers it
from cananalyze.formats.registry import FORMATS, FrameWriter

# the formats we write, by suffix (each format's module declares its own)
WRITTEN = {
    f.write_suffix: f for f in sorted(FORMATS, key=lambda f: f.write_suffix) if f.writer is not None
}


def written_names(*more: str) -> str:
    """ ".asc, .blf or .log (candump)" (and `more` suffixes): for messages."""
    names = [s if f.name == s[1:] else f"{s} ({f.name})" for s, f in WRITTEN.items()]
    names += more
    return ", ".join(names[:-1]) + " or " + names[-1]


def LogWriter(path: str | Path) -> FrameWriter:  # noqa: N802 - a class's factory, named as one
    """The writer of the format `path`'s suffix names."""
    fmt = WRITTEN.get(Path(path).suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: write {written_names()}")
    return fmt.writer(Path(path))


def write_log(batch: FrameBatch, path: str | Path) -> None:
    """Write a batch as its suffix says, atomically (core/atomic)."""
    path = Path(path)
    if path.suffix.lower() not in WRITTEN:
        raise ValueError(f"{path}: write {written_names()}")
    with atomic_path(path) as tmp:  # keeps the suffix: the format comes from it
        writer = LogWriter(tmp)
        try:
            writer.write(batch)
        finally:
            writer.close()
