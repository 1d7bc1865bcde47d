"""open_log(): the one facade from a path (or '-') to a stream of FrameBatch.

Decompresses .gz, reads stdin, picks the format from the content (suffix only
breaks ties), and turns unreadable files into one-line InputErrors.
"""

from __future__ import annotations

import gzip
import importlib
import io
import os
import pkgutil
import stat
import sys
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from cananalyze.core import storage
from cananalyze.core.errors import InputError, ProblemLog, UsageError
from cananalyze.core.frames import FrameBatch
from cananalyze.formats import logs, registry
from cananalyze.formats.registry import DEFAULT_BATCH, LogFormat, ReadContext

SNIFF_BYTES = 65536  # the first look: most logs are told from this much
# A log whose frames come later (after a long header, or a line longer than the first
# look) is read on, the head doubling each round and every format asked again, until
# one claims it or this much has been read: bytes, or lines, whichever comes first
DETECT_BYTES = 8 << 20
DETECT_LINES = 10000

# every module of formats/logs/: each registers its LogFormat as it is imported
for _module in pkgutil.iter_modules(logs.__path__):
    importlib.import_module(f"{logs.__name__}.{_module.name}")


def _describe(head: bytes) -> str:
    """A few words on what an unrecognised file looks like, for the error message."""
    if not head:
        return "the file is empty"
    if head[:4] == b"LOGG":
        return "it looks like a BLF file but no BLF reader is available"
    if head[:4] == b"PK\x03\x04":
        return "it looks like a ZIP file, not a CAN log"
    text = sum(32 <= c < 127 or c in (9, 10, 13) for c in head[:4096]) / max(1, len(head[:4096]))
    if text < 0.9:
        return "it is binary data of no known CAN log format"
    lower = head[:4096].lower()
    if b"[fileinfo]" in lower or b"[deviceinfo]" in lower:
        return "it is an EDS/DCF device description, not a log (give it with --eds NODE=FILE)"
    if lower.startswith(b"version") and b"bo_ " in lower:
        return "it is a DBC database, not a log"
    first = head.splitlines()[0][:60].decode("latin-1", "replace") if head.strip() else ""
    return f"it is text of no known CAN log format (first line: {first!r})"


class _TolerantGzip(io.RawIOBase):
    """gzip stream that hands over what it decompressed before a cut or corrupt end.

    GzipFile.read(n) raises EOFError and drops the partial block, which would lose
    frames a half-copied log still holds; read1() in a loop keeps them. The bytes after
    the last newline wait until more comes: when the data breaks off, that incomplete
    line is dropped (`dropped`), not read as a frame ("(t) can0 285#" cut from its data
    bytes is a valid empty frame to a text reader). A binary stream's tail waits at most
    TAIL_MAX bytes.
    """

    TAIL_MAX = 1 << 16

    def __init__(self, raw: BinaryIO) -> None:
        self._raw = raw
        self._gz = gzip.GzipFile(fileobj=raw, mode="rb")
        self.error: str | None = None
        self.offset = 0  # compressed bytes read when the error came (it is at or before)
        self.dropped = 0  # bytes of an incomplete last line left out after the error
        self._out = memoryview(b"")
        self._tail = b""
        self._ended = False

    def readable(self) -> bool:
        return True

    def readinto(self, buf) -> int:  # type: ignore[override]
        while not self._out:
            if self.error or self._ended:
                return 0
            try:
                data = self._gz.read1(max(len(buf), self.TAIL_MAX))
            except (EOFError, gzip.BadGzipFile, zlib.error, OSError) as exc:
                self.error = str(exc) or exc.__class__.__name__
                try:
                    self.offset = self._raw.tell()
                except (OSError, ValueError):
                    self.offset = 0
                self.dropped, self._tail = len(self._tail), b""
                return 0
            if not data:
                self._ended = True
                self._out, self._tail = memoryview(self._tail), b""
                continue
            data = self._tail + data
            cut = data.rfind(b"\n") + 1
            if len(data) - cut > self.TAIL_MAX:
                cut = len(data)
            self._out, self._tail = memoryview(data)[:cut], data[cut:]
        n = min(len(buf), len(self._out))
        buf[:n] = self._out[:n]
        self._out = self._out[n:]
        return n

    def close(self) -> None:
        self._gz.close()
        super().close()


@dataclass
class LogSource:
    """An opened log: its format, the reading context, and its batches (read once)."""

    path: str
    fmt: LogFormat
    ctx: ReadContext
    _stream: BinaryIO
    _closers: list = field(default_factory=list)
    strict: bool = False
    size: int | None = None  # bytes of the file on disk (None: stdin, a pipe)

    def fraction(self) -> float | None:
        """How far into the file the reader is (0..1), from the position on disk; None
        when the size is unknown. A compressed file reports its compressed position."""
        if not self.size or not self._closers:
            return None
        try:
            return min(1.0, self._closers[0].tell() / self.size)
        except (OSError, ValueError):
            return None

    @property
    def problems(self) -> ProblemLog:
        return self.ctx.problems

    def batches(self) -> Iterator[FrameBatch]:
        """The log's frames in batches; in strict mode, those before the first problem, then InputError.

        Readers always run leniently; strictness is applied here, once for every
        format, so the frames read before a bad line are never lost.
        """
        frames = 0
        for batch in self._lenient_batches():
            frames += len(batch)
            if self.strict and self.ctx.problems.count:
                first = self.ctx.problems.shown[0]
                kind, _, number = first.location.partition(" ")
                if kind in ("line", "record", "message") and number.isdecimal():
                    batch = batch.take(batch.line < int(number))
                if len(batch):
                    yield batch
                raise InputError(str(first))
            yield batch
        if self.ctx.problems.count and (self.strict or not frames):
            # a file of which nothing could be read is a failure, not "0 frames"
            first = self.ctx.problems.shown[0]
            if self.strict:
                raise InputError(str(first))
            n = self.ctx.problems.count
            raise InputError(f"{first} (no frame could be read; {n} problem(s) in all)")

    def _lenient_batches(self) -> Iterator[FrameBatch]:
        try:
            yield from self.fmt.read(self._stream, self.ctx)
            for c in self._closers:
                if isinstance(c, _TolerantGzip) and c.error:
                    self.ctx.problems.add(
                        self.path,
                        f"after frame {self.ctx.frames}",
                        f"corrupt gzip at or before compressed byte {c.offset:,}: "
                        f"the data ends early or is damaged ({c.error})"
                        + (
                            f"; its last {c.dropped} bytes, an incomplete line, left out"
                            if c.dropped
                            else ""
                        ),
                    )
        except (EOFError, zlib.error, gzip.BadGzipFile) as exc:
            self.ctx.problems.add(
                self.path,
                f"after frame {self.ctx.frames}",
                f"file ends early or is corrupt ({exc})",
            )
        except OSError as exc:
            raise InputError(f"{self.path}: cannot read: {exc.strerror or exc}") from None
        finally:
            self.close()

    def close(self) -> None:
        for c in self._closers:
            c.close()
        self._closers.clear()


def _forced(name: str, forced: str) -> LogFormat:
    formats = registry.FORMATS
    for f in formats:
        if f.name == forced:
            return f
    raise InputError(
        f"{name}: unknown format {forced!r} (known: {', '.join(f.name for f in formats)})"
    )


def _claim(head: bytes, name: str, text: bool | None = None) -> LogFormat | None:
    """The format whose sniffer claims the head (the suffix breaks ties), or None;
    `text` asks only the text (True) or the binary (False) formats."""
    suffix = Path(name[:-3] if name.endswith(".gz") else name).suffix.lower()
    formats = [f for f in registry.FORMATS if text is None or f.text == text]
    claims = [f for f in formats if _safe_sniff(f, head)]
    for f in claims:
        if suffix in f.suffixes:
            return f
    return claims[0] if claims else None


def _detect(stream: BinaryIO, head: bytes, ended: bool, name: str, pipe: bool, cr_only: bool):
    """(format, head): the format told from the head, reading on when none claims it.

    The first SNIFF_BYTES tell nearly every log. When they do not (a TRC whose frames
    come after a line longer than that, a candump capture after a long header), the
    head is read on, doubling, and every format is asked again each round, up to
    DETECT_BYTES or DETECT_LINES; a log that none claims by then is refused in one
    line. The head returned is every byte read, for the readers to see again.
    """
    text = True if cr_only else None  # repaired line ends: only a text format may claim them
    chosen = _claim(head, name, text)
    target = SNIFF_BYTES
    while chosen is None and not ended and len(head) < DETECT_BYTES:
        if head.count(b"\n") >= DETECT_LINES:
            break
        target = min(2 * target, DETECT_BYTES)
        more, ended = _read_upto(stream, target - len(head), pipe)
        if not more:
            break
        if cr_only:
            more = more.replace(b"\r", b"\n")
        head += more
        chosen = _claim(_first_lines(head, DETECT_LINES), name, text)
    if chosen is None:
        raise InputError(f"{name}: not a log cananalyze can read: {_describe(head[:SNIFF_BYTES])}")
    return chosen, head


def _first_lines(head: bytes, lines: int) -> bytes:
    """The head up to the end of its `lines`-th line (all of it when it has fewer)."""
    if head.count(b"\n") <= lines:
        return head
    at = -1
    for _ in range(lines):
        at = head.index(b"\n", at + 1)
    return head[: at + 1]


def _safe_sniff(fmt: LogFormat, head: bytes) -> bool:
    try:
        return bool(fmt.sniff(head))
    except Exception:  # a sniffer must never take the program down on odd bytes
        return False


def open_log(
    path: str | Path,
    strict: bool = False,
    batch_size: int = DEFAULT_BATCH,
    fmt: str | None = None,
    problems: ProblemLog | None = None,
    storage_options: dict | None = None,
) -> LogSource:
    """Open a log (a path, "-" for stdin, or an fsspec URL: core/storage) for batch
    reading; raises InputError with a one-line reason."""
    name = path if storage.is_url(path) else str(path)
    closers: list = []
    try:
        if name == "-":
            if sys.stdin is None:  # `decode - <&-`: no file descriptor 0 at all
                raise InputError("-: standard input is closed, nothing to read")
            raw: BinaryIO = sys.stdin.buffer
        else:
            raw = storage.open_binary(name, storage_options)
            closers.append(raw)
    except UsageError as exc:  # an unknown protocol, a missing extra: this log's reason
        raise InputError(str(exc)) from None
    except FileNotFoundError:
        raise InputError(f"{name}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{name}: is a directory, not a log file") from None
    except OSError as exc:
        raise InputError(f"{name}: cannot open: {exc.strerror or exc}") from None
    stream: BinaryIO = raw if hasattr(raw, "peek") else io.BufferedReader(raw)  # type: ignore[arg-type]
    magic = stream.peek(2)[:2]
    gz = None
    if magic == b"\x1f\x8b":
        gz = _TolerantGzip(stream)
        closers.append(gz)
        stream = io.BufferedReader(gz, buffer_size=SNIFF_BYTES)  # type: ignore[assignment]
    pipe = stream is raw and not storage.is_url(name) and not _regular(raw)
    try:
        head, ended = _read_upto(stream, SNIFF_BYTES, pipe)
        if gz is not None and gz.error and not head:  # not "the file is empty"
            raise InputError(
                f"{name}: corrupt gzip at or before compressed byte {gz.offset:,}: {gz.error}"
            )
        bom = len(_BOM) if head.startswith(_BOM) else 0  # no part of the first line or 'date'
        head = head[bom:]
        # Classic Mac line ends (CR only) are made newlines for the text formats alone,
        # after the format is known: a binary file whose head has a 0x0D and no 0x0A (a
        # pcap's microseconds 0x00030D40) is read byte for byte
        cr = b"\r" in head and b"\n" not in head
        if fmt:
            chosen = _forced(name, fmt)
        else:
            chosen = _claim(head, name, text=False) if cr else None
            if chosen is None:
                chosen, head = _detect(
                    stream, head.replace(b"\r", b"\n") if cr else head, ended, name, pipe, cr
                )
        cr_only = cr and chosen.text
        if cr_only and fmt:
            head = head.replace(b"\r", b"\n")
    except (EOFError, gzip.BadGzipFile, zlib.error, OSError) as exc:
        for c in closers:
            c.close()
        raise InputError(f"{name}: cannot read: {exc}") from None
    except InputError:
        for c in closers:
            c.close()
        raise
    if stream.seekable() and not cr_only:
        stream.seek(bom)  # a file: read again from the start (the MCAP reader seeks)
    else:
        stream = io.BufferedReader(_Replay(head, stream, cr_only), buffer_size=SNIFF_BYTES)  # type: ignore[assignment]
    ctx = ReadContext(source=name, problems=problems or ProblemLog(), batch_size=batch_size)
    size = None
    if storage.is_url(name):
        size = getattr(raw, "size", None)  # fsspec's files know theirs
    elif name != "-":
        try:
            st = os.fstat(raw.fileno())
            size = st.st_size if stat.S_ISREG(st.st_mode) else None
        except (OSError, ValueError):
            size = None
    return LogSource(name, chosen, ctx, stream, closers, strict=strict, size=size)


_BOM = b"\xef\xbb\xbf"


def _regular(raw) -> bool:
    try:
        return stat.S_ISREG(os.fstat(raw.fileno()).st_mode)
    except (OSError, ValueError, AttributeError):
        return False


def _read_upto(stream: BinaryIO, size: int, pipe: bool) -> tuple[bytes, bool]:
    """(up to `size` bytes of the stream, whether it ended). One peek gives only one buffer,
    8 KB: a TRC whose frames start later was refused. A pipe stops early when its writer
    pauses for half a second, so `candump can0 | cananalyze decode -` starts at once."""
    import select

    parts: list[bytes] = []
    got = 0
    ended = False
    while got < size:
        part = stream.read1(size - got)  # type: ignore[attr-defined]
        if not part:
            ended = True
            break
        parts.append(part)
        got += len(part)
        if pipe:
            try:  # read1 took the whole buffer: the descriptor tells if more is waiting
                if not select.select([stream], [], [], 0.5)[0]:
                    break
            except (OSError, ValueError, TypeError):
                pipe = False
    return b"".join(parts), ended


class _Replay(io.RawIOBase):
    """The head read for detection, then the rest of the stream: readers see the whole file.
    `cr_only` turns classic Mac line ends into newlines (else such a log is one long line)."""

    def __init__(self, head: bytes, rest: BinaryIO, cr_only: bool = False) -> None:
        self._head = memoryview(head)
        self._rest = rest
        self._cr_only = cr_only

    def readable(self) -> bool:
        return True

    def readinto(self, buf) -> int:  # type: ignore[override]
        if self._head:
            n = min(len(buf), len(self._head))
            buf[:n] = self._head[:n]
            self._head = self._head[n:]
            return n
        data = self._rest.read1(len(buf))  # type: ignore[attr-defined]
        if self._cr_only:
            data = data.replace(b"\r", b"\n")
        buf[: len(data)] = data
        return len(data)


def read_all(path: str | Path, strict: bool = False, fmt: str | None = None) -> FrameBatch:
    """Every frame of a small log in one batch (tests, samples, notebooks)."""
    from cananalyze.core.frames import concat

    src = open_log(path, strict=strict, fmt=fmt)
    return concat(src.batches())
