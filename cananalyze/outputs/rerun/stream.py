"""Rerun export batch by batch (the entities of `send`), memory flat in log length.

To an .rrd file (`export --rrd`) or a viewer (`decode --rerun / --connect`).

Sending a whole Capture peaked at 1.1 GB for a 5M-frame log. Here each decoded
batch becomes a small Capture of its own (the same Collector, NMT states carried
across batches so lanes show changes only) whose signals, states and events go
out with `send_columns` at once. The bus load is summed into its windows as
frames come (a float per 0.1 s: 290 KB for an hour), per bus on a log of several, and
sent at the end with `busload.load_series`'s rule for the last window. The layout
(blueprint) names every PDO and NMT lane, so it is sent when all are known:
after the data, as the recording's default.
"""

from __future__ import annotations

import contextlib
import errno
from pathlib import Path

import numpy as np

from cananalyze.core.atomic import atomic_path
from cananalyze.core.errors import ProblemLog
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.events.build import EventState
from cananalyze.outputs.capture import Collector
from cananalyze.outputs.rerun.send import (
    LOAD_WINDOW,
    Layout,
    grpc_url,
    is_absolute,
    recording,
    send_header,
    send_load,
    send_parts,
)
from cananalyze.protocol.busload import bits_by_channel, load_windows


class StreamRrd:
    """Context manager: `add()` each DecodedBatch, `close()` at the end; the file appears
    (atomically) only then."""

    def __init__(
        self,
        path: str | Path | None,
        source: str = "",
        network: str = "",
        bitrate: int | None = None,
        connect: str | None = None,
    ) -> None:
        """To the file `path`; or, without one, to the running viewer at `connect` (gRPC
        URL or host:port) or to a spawned viewer."""

        self.source = str(source)
        self.bitrate = bitrate
        self.counts: dict[str, int] = {}
        self._stack = contextlib.ExitStack()
        self.rec = recording(Path(self.source).name)
        self._file = path is not None
        self.path = Path(path) if path is not None else None
        self._tmp: Path | None = None
        self._dead = False  # rerun's file writer failed: nothing more reaches the file
        if path is not None:
            self._tmp = self._stack.enter_context(atomic_path(path))
            with self._named_errors():
                self.rec.save(self._tmp)
        elif connect:
            self.rec.connect_grpc(grpc_url(connect))
        else:
            self.rec.spawn()
        send_header(self.rec, self.source, network or "")
        self._named: set[str] = set()
        self._layout = Layout()
        self._absolute: bool | None = None
        self._event_state = EventState()
        self._load: dict[str, _LoadWindows] = {}  # channel name -> its bus load windows
        self._t0: float | None = None  # the first frame's time: every bus's windows align to it

    def __enter__(self) -> StreamRrd:
        return self

    def __exit__(self, typ, exc, tb) -> None:
        if exc is not None:
            self.abort(typ, exc, tb)

    def add(self, batch: DecodedBatch) -> None:
        """Send the batch's signals, NMT states and events; count its bits for the bus load."""
        col = Collector(self.source, self._event_state, records=False)
        col.add(batch)
        cap = col.capture(ProblemLog())
        fb = batch.frames
        if self._absolute is None and len(fb):
            self._absolute = is_absolute(fb.t)
        self._layout.add(cap)
        with self._named_errors():
            send_parts(cap, self.rec, bool(self._absolute), self.counts, self._named)
        if len(fb):
            self._add_load(fb)

    def _add_load(self, fb) -> None:
        """The batch's frame bits into their bus's windows (one bus: all of them)."""
        if self._t0 is None:
            self._t0 = float(fb.t[0])
        for label, (t, bits) in bits_by_channel(fb).items():
            windows = self._load.get(label)
            if windows is None:
                windows = self._load[label] = _LoadWindows(LOAD_WINDOW, self._t0)
            windows.add(t, bits)

    def close(self) -> dict[str, int]:
        """Bus load, the layout and the end of the recording; the file replaces its target.
        Returns value counts per entity."""
        counts = self.finish()
        self.commit()
        return counts

    def commit(self) -> None:
        """The finished file replaces its target."""
        self._stack.close()

    def finish(self) -> dict[str, int]:
        """close() but the rename."""
        try:
            several = len(self._load) > 1
            for label, windows in self._load.items():
                starts, load = windows.series(self.bitrate)
                path = send_load(
                    self.rec,
                    label if several else None,
                    starts,
                    load,
                    bool(self._absolute),
                    self.bitrate,
                    self.counts,
                    self._named,
                )
                self._layout.loads.add(path)
            self.rec.send_blueprint(self._layout.blueprint(), make_active=True, make_default=True)
            with self._named_errors():
                self._flush()
                if self._file:  # a viewer keeps the recording; the file needs its end
                    self.rec.disconnect()
        except BaseException as exc:
            self.abort(type(exc), exc, exc.__traceback__)
            raise
        return self.counts

    @contextlib.contextmanager
    def _named_errors(self):
        """Rerun reports a failed write (a full disk) as RuntimeError from its writer
        thread, naming its temporary file: an OSError naming the output instead."""
        try:
            yield
        except RuntimeError as exc:
            if self.path is None or "write" not in str(exc).lower():
                raise
            self._writer_failed()
            raise OSError(
                errno.ENOSPC if "space" in str(exc) else errno.EIO,
                f"cannot write the Rerun recording ({_cause(exc)})",
                str(self.path),
            ) from None

    def _flush(self) -> None:
        """rec.flush(), which waits forever once rerun's file writer has failed (its error
        only goes to the log): wait in steps while the file still grows."""
        if self._tmp is None or not self._tmp.exists():
            self.rec.flush()
            return
        size = -1
        while True:
            try:
                self.rec.flush(timeout_sec=FLUSH_STEP)
                return
            except Exception:  # noqa: BLE001 - rerun raises a plain error on its timeout
                now = self._tmp.stat().st_size
                if now == size:
                    self._writer_failed()
                    raise OSError(
                        errno.EIO,
                        "Rerun stopped writing the recording (disk full or file too large?)",
                        str(self.path),
                    ) from None
                size = now

    def _writer_failed(self) -> None:
        """Rerun's file writer has failed (a full disk). disconnect(), the stream's
        __del__ and rerun's own exit hook (which flushes every recording) would each wait
        for it forever: a process that failed this way hung at exit, intermittently
        (py-spy: `rerun_shutdown`, and `RecordingStream.__del__` when the stream was only
        kept in a module's list, which interpreter shutdown clears). So the dead stream is
        never disconnected and never freed (one reference no one gives back), and rerun's
        exit hook is dropped; the outputs flush and close their recordings themselves."""
        import ctypes

        import rerun as rr

        self._dead = True
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(self.rec))
        rr.unregister_shutdown()

    def abort(self, typ=None, exc=None, tb=None) -> None:
        """Stop the recording and drop the temporary file."""
        if not self._dead:
            with contextlib.suppress(Exception):
                self.rec.disconnect()
        self._stack.__exit__(typ or RuntimeError, exc or RuntimeError("aborted"), tb)


FLUSH_STEP = 5.0  # s: a flush that writes nothing for two steps has failed


def _cause(exc: BaseException) -> str:
    text = str(exc)
    return text.rpartition("Failed to write: ")[2] or text


class _LoadWindows:
    """Bits per window, windows aligned to t0 (the first frame's time unless given),
    summed batch by batch."""

    def __init__(self, window: float, t0: float | None = None) -> None:
        self.window = window
        self.t0 = t0
        self.first = 0  # window index of sums[0] (negative when times went back before t0)
        self.sums = np.zeros(0)
        self.t_last = 0.0

    def add(self, t: np.ndarray, bits: np.ndarray) -> None:
        if self.t0 is None:
            self.t0 = float(t[0])
        idx = np.floor((t - self.t0) / self.window).astype(np.int64)
        lo, hi = int(idx.min()), int(idx.max())
        if not self.sums.size:
            self.first = lo
        if lo < self.first:
            self.sums = np.concatenate([np.zeros(self.first - lo), self.sums])
            self.first = lo
        need = hi - self.first + 1
        if need > self.sums.size:
            self.sums = np.concatenate([self.sums, np.zeros(need - self.sums.size)])
        self.sums += np.bincount(idx - self.first, weights=bits, minlength=self.sums.size)
        self.t_last = float(t[-1])

    def series(self, bitrate: int | None) -> tuple[np.ndarray, np.ndarray]:
        if self.t0 is None or not self.sums.size:
            return np.zeros(0), np.zeros(0)
        start = self.t0 + self.first * self.window  # sums[0]'s window (a later bus's is not t0's)
        return load_windows(self.sums.copy(), start, self.t_last, self.window, bitrate)
