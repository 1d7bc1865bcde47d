"""Write outputs atomically: into a temporary file next to the target, then rename.

A cut-off export (Ctrl-C, full disk, a crash) must not leave a half-written file
that a viewer then fails to open or, worse, half-shows.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import UsageError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_writable(dest: str | Path) -> None:
    """Fail before a long decode when the output's directory is missing."""
    parent = Path(dest).parent if str(Path(dest).parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"{dest}: directory {parent} does not exist")
    if Path(dest).is_dir():
        raise UsageError(f"{dest}: is a directory, give a file name")


@contextlib.contextmanager
def atomic_path(dest: str | Path) -> Iterator[Path]:
    """A temporary path to write; renamed to `dest` when the block ends without error."""
    dest = Path(dest)
    check_writable(dest)
    parent = dest.parent if str(dest.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give what open() would
        os.replace(tmp, dest)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text_atomic(dest: str | Path, text: str) -> None:
    """A whole text file (JUnit, JSON reports) written atomically."""
    with atomic_path(dest) as tmp:
        tmp.write_text(text, encoding="utf-8")
