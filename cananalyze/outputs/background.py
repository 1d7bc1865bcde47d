"""Writing finished output bytes from a worker thread, while the caller decodes on.

The text and JSONL writers build each batch's lines as column blocks (numpy plus
some Python, which stays in the caller: a thread that often releases and re-takes
the GIL would wait on the decoder every time). The last steps, compacting the
blocks (C, without the GIL; `Rendered.bytes`) and writing them, are done here.
The queue is one batch deep: a rendered batch's blocks are ~50 MB at 256k rows.
"""

from __future__ import annotations

import queue
import threading
from typing import Protocol, TextIO


class Finishable(Protocol):
    def bytes(self) -> bytes:
        """The finished bytes."""

    def pieces(self) -> list:
        """The finished bytes as bytes-like pieces, in order (no join)."""


class ByteSink:
    """Bytes (or things that finish into bytes) to a text stream, through its binary
    buffer when it is UTF-8; with `background`, by a worker thread. `close()` waits
    for the worker and raises what it raised."""

    def __init__(self, out: TextIO, background: bool, name: str) -> None:
        self.out = out
        self._queue: queue.Queue | None = None
        self._worker: threading.Thread | None = None
        self._error: BaseException | None = None
        if background and self.buffer() is not None:
            self.out.flush()
            self._queue = queue.Queue(maxsize=1)
            self._worker = threading.Thread(target=self._work, name=name, daemon=True)
            self._worker.start()

    @property
    def background(self) -> bool:
        return self._queue is not None

    def put(self, data: bytes | Finishable) -> None:
        if self._queue is None:
            self._emit(data)
            return
        if self._error is not None:
            self.close()
        self._queue.put(data)

    def close(self) -> None:
        """Wait for the worker, if any; re-raise its error here."""
        if self._worker is not None:
            if self._worker.is_alive():
                self._queue.put(None)
                self._worker.join()
            self._worker = None
            self._queue = None
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def _work(self) -> None:
        buffer = self.buffer()
        while True:
            data = self._queue.get()
            if data is None:
                return
            if self._error is None:  # after an error, drain so the caller never blocks
                try:
                    _write(buffer, data)
                except BaseException as exc:  # noqa: BLE001 - re-raised by close()
                    self._error = exc

    def buffer(self):
        """The binary buffer under a UTF-8 text stream, else None."""
        buffer = getattr(self.out, "buffer", None)
        encoding = getattr(self.out, "encoding", "") or ""
        if buffer is not None and encoding.lower().replace("-", "") == "utf8":
            return buffer
        return None

    def _emit(self, data: bytes | Finishable) -> None:
        buffer = self.buffer()
        if buffer is not None:
            self.out.flush()
            _write(buffer, data)
        else:
            self.out.write((data if isinstance(data, bytes) else data.bytes()).decode("utf-8"))


def _write(buffer, data: bytes | Finishable) -> None:
    """Bytes, or a finished batch piece by piece: not joined into one more copy."""
    if isinstance(data, bytes):
        buffer.write(data)
        return
    for piece in data.pieces():
        buffer.write(piece)
