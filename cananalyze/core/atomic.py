"""Atomic output files: an interrupted export leaves the complete old file, the new one, or none.

Every writer puts its bytes in a temporary file next to the target (same
directory, so the final rename never crosses file systems), and renames it over
the target only when writing finished without an exception. Ctrl-C, a full disk
or a crash mid-way leave no half-written file that a later tool would misread.
Targets that are not regular files (`/dev/null`, a FIFO, a terminal) are written
directly: renaming over them would replace the device with a file.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import socket
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from cananalyze.core.errors import UsageError


def check_writable(dest: str | os.PathLike) -> None:
    """Fail before a long decode when the output's directory is missing."""
    parent = Path(dest).parent if str(Path(dest).parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"{dest}: directory {parent} does not exist")
    if Path(dest).is_dir():
        raise UsageError(f"{dest}: is a directory, give a file name")


def _special(path: Path) -> bool:
    try:
        return not stat.S_ISREG(path.stat().st_mode)
    except FileNotFoundError:
        return False


def _suffix(path: Path) -> str:
    """The suffix libraries choose their format by, kept on the temporary name ('.log.gz' too)."""
    return "".join(path.suffixes[-2:]) if path.suffix.lower() == ".gz" else path.suffix


def _file_mode(path: Path) -> int:
    """Mode the file would get from a plain open(): the old file's, else 0o666 less the umask."""
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except FileNotFoundError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


# Temporary files carry this machine and the process that writes them: a run killed with
# SIGKILL (no handler runs) leaves its files behind, and the next run in that folder on this
# machine removes those whose process is gone (`sweep`).
_HOST = hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]
_TAG = re.compile(r"^\..*\.cananalyze-([0-9a-f]{8})-(\d+)-[^/]*$")
_swept: set[Path] = set()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process: alive
        return True
    return True


def sweep(folder: Path) -> list[Path]:
    """Remove the temporary files that runs on this machine left in `folder` when they were
    killed (their process is gone); the files removed. Once per folder and process."""
    folder = folder.resolve() if folder.exists() else folder
    if folder in _swept:
        return []
    _swept.add(folder)
    gone = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return gone
    for e in entries:
        m = _TAG.match(e.name)
        if m is None or m.group(1) != _HOST or int(m.group(2)) == os.getpid():
            continue
        if not _alive(int(m.group(2))):
            with contextlib.suppress(OSError):
                os.unlink(e.path)
                gone.append(Path(e.path))
    return gone


def _temp_beside(path: Path) -> tuple[int, Path]:
    """A new hidden temporary file next to `path` (same file system: the rename is atomic),
    keeping the suffix libraries choose their format by; an error names `path`, the file
    the user asked for, not the temporary one."""
    sweep(path.parent)
    prefix = f".{path.stem}.cananalyze-{_HOST}-{os.getpid()}-"
    try:
        fd, name = tempfile.mkstemp(prefix=prefix, suffix=_suffix(path), dir=path.parent)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
    return fd, Path(name)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary filename to write; it replaces ``path`` when the block ends without error.

    For libraries that want a filename (python-can writers, mcap, pyarrow, rerun).
    On an exception the temporary file is removed and ``path`` is left as it was.
    The temporary name keeps the suffix (python-can writers choose the format by it).
    Raises UsageError when the directory is missing or ``path`` is a directory.
    """
    path = Path(path)
    check_writable(path)
    if _special(path):
        yield path
        return
    fd, tmp = _temp_beside(path)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, _file_mode(path))
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike,
    mode: str = "w",
    encoding: str | None = None,
    newline: str | None = None,
) -> Iterator[IO]:
    """``open(path, mode)`` whose result appears at ``path`` only once complete (flushed and synced)."""
    if "r" in mode or "a" in mode or "+" in mode:
        raise ValueError(f"atomic_write writes a new file; mode {mode!r} is not supported")
    if "b" not in mode and encoding is None:
        encoding = "utf-8"
    with atomic_path(path) as tmp, open(tmp, mode, encoding=encoding, newline=newline) as f:
        yield f
        f.flush()
        if tmp != Path(path):  # a device or FIFO written directly cannot fsync
            os.fsync(f.fileno())


def write_text_atomic(dest: str | os.PathLike, text: str) -> None:
    """A whole text file (JUnit, JSON reports) written atomically."""
    with atomic_write(dest, "w", encoding="utf-8") as f:
        f.write(text)


class Staged:
    """One output file written in full now and put in place later (`commit`), or dropped
    (`abort`): how a sink whose output is one text (JUnit, JSON) takes part in the
    pipeline's all-or-nothing commit, which only renames."""

    def __init__(self, dest: str | os.PathLike) -> None:
        self.dest = Path(dest)
        self.tmp: Path | None = None
        # for a special file (/dev/stdout): the text, written at commit
        self.text: str | Iterable[str] | None = None

    def write_text(self, text: str | Iterable[str]) -> None:
        """`text`: a str, or its pieces (a generator: the whole text is never held)."""
        check_writable(self.dest)
        if _special(self.dest):
            self.text = text  # pieces are produced at commit, as they are written
            return
        fd, self.tmp = _temp_beside(self.dest)
        try:
            with self._named(), os.fdopen(fd, "w", encoding="utf-8") as f:
                _write(f, text)
                f.flush()
                os.fsync(f.fileno())  # as atomic_write: complete on disk before the rename
            os.chmod(self.tmp, _file_mode(self.dest))
        except BaseException:
            self.abort()
            raise

    def commit(self) -> None:
        if self.tmp is not None:
            os.replace(self.tmp, self.dest)
            self.tmp = None
        elif self.text is not None:
            text, self.text = self.text, None
            with self._named(), open(self.dest, "w", encoding="utf-8") as f:
                _write(f, text)

    def abort(self) -> None:
        if self.tmp is not None:
            with contextlib.suppress(OSError):
                self.tmp.unlink()
            self.tmp = None
        self.text = None

    @contextlib.contextmanager
    def _named(self) -> Iterator[None]:
        """A write error without a file name (a full disk) names this file: a sink writing
        two (JUnit and JSON) has no one `dest` for the pipeline to name."""
        try:
            yield
        except OSError as exc:
            if exc.filename:
                raise
            raise OSError(exc.errno, exc.strerror or str(exc), str(self.dest)) from exc


def _write(f: IO, text: str | Iterable[str]) -> None:
    if isinstance(text, str):
        f.write(text)
    else:
        for piece in text:
            f.write(piece)
