"""FrameRecorder: the raw frames of a live session, saved as candump, ASC, BLF or MCAP.

Log formats go through `logfile.LogWriter`, the writer each format's module registers
(candump as candump -l writes it; ASC and BLF by python-can's writers). MCAP has no python-can writer: the
frames go on the `/can/frames` topic in the export's `cananalyze.Frame` schema,
built column-wise by the export's own payload builder and written as chunked,
indexed MCAP by its bulk writer (`formats/mcap_frames.py`, `mcap_bulk.py`), so a
recording and an export read back the same way. `close()` finalises the file (BLF
header counts, MCAP summary), which is what keeps a recording valid when a live
session is interrupted.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from cananalyze.core.errors import UsageError
from cananalyze.core.frames import FrameBatch, concat
from cananalyze.core.records import DecodedBatch
from cananalyze.formats.logfile import WRITTEN, LogWriter, written_names


class FrameRecorder:
    """Write every FrameBatch it is given to `path`; the format comes from the suffix."""

    @staticmethod
    def check_suffix(path: str | Path) -> None:
        suffix = Path(path).suffix.lower()
        if suffix != ".mcap" and suffix not in WRITTEN:
            raise UsageError(f"--record {path}: use a {written_names('.mcap')} file")

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.frames = 0
        self._logger = None
        self._mcap: McapRecording | None = None
        self.check_suffix(path)
        suffix = self.path.suffix.lower()
        try:
            if suffix == ".mcap":
                self._mcap = McapRecording(self.path)
            else:
                self._logger = LogWriter(self.path)
        except OSError as exc:
            raise UsageError(f"--record {path}: cannot write: {exc.strerror or exc}") from None

    def write(self, batch: FrameBatch | DecodedBatch) -> None:
        """Record a batch; a DecodedBatch also gives MCAP its service and node columns."""
        fb = batch.frames if isinstance(batch, DecodedBatch) else batch
        if not len(fb):
            return
        if self._mcap is not None:
            self._mcap.write(batch)
        else:
            self._logger.write(fb)
        self.frames += len(fb)

    def flush(self) -> None:
        """The frames recorded so far onto the file: a recording killed after this
        (SIGKILL) keeps them, readable (the candump, ASC and BLF text or containers, MCAP
        chunks without the summary)."""
        if self._mcap is not None:
            self._mcap.flush()
        elif self._logger is not None:
            self._logger.flush()

    def close(self) -> None:
        """Finalise the file (idempotent)."""
        if self._mcap is not None:
            self._mcap.close()
        elif self._logger is not None:
            self._logger.close()
            self._logger = None


class McapRecording:
    """Live frames on `/can/frames`, gathered for about a second (or FLUSH_FRAMES) and
    written as one chunk: at 32k frames/s a batch comes every 50 ms, and a chunk per
    batch would make the summary's chunk index grow by 20 entries a second.

    service and node come from the decoded batch when the caller has one, else from
    the predefined connection set (`CobClassifier`; a remapped PDO then shows as the
    service its COB-ID has by default).
    """

    FLUSH_FRAMES = 32768
    FLUSH_SECONDS = 1.0

    def __init__(self, path: Path) -> None:
        from cananalyze.core.version import __version__
        from cananalyze.formats.mcap_bulk import BulkMcapWriter
        from cananalyze.formats.mcap_frames import FRAME_SCHEMA, FRAME_SCHEMA_NAME, FRAMES_TOPIC
        from cananalyze.protocol.cobid import CobClassifier

        self.path = path
        self._file = open(path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = BulkMcapWriter(self._file, f"cananalyze {__version__}")
        schema = self._writer.schema(
            FRAME_SCHEMA_NAME, "jsonschema", json.dumps(FRAME_SCHEMA).encode()
        )
        self._channel = self._writer.channel(FRAMES_TOPIC, "json", schema)
        self._file.flush()  # header, schema and channel: a killed recording still says what it is
        self._classifier = CobClassifier()
        self._pending: list[tuple[FrameBatch, np.ndarray, np.ndarray]] = []
        self._waiting = 0
        self._since = 0.0  # monotonic time the oldest pending batch came
        self.frames = 0

    def write(self, batch: FrameBatch | DecodedBatch) -> None:
        if isinstance(batch, DecodedBatch):
            fb, service, node = batch.frames, batch.service, batch.node
        else:
            c = self._classifier.classify(batch)
            fb, service, node = batch, c.service, c.node
        if not self._pending:
            self._since = time.monotonic()
        self._pending.append((fb, service, node))
        self._waiting += len(fb)
        if (
            self._waiting >= self.FLUSH_FRAMES
            or time.monotonic() - self._since >= self.FLUSH_SECONDS
        ):
            self.flush()

    def flush(self) -> None:
        """Write the pending frames as a chunk (in time order: the writer needs it)."""
        from cananalyze.formats.mcap_frames import frame_payloads, log_time_ns

        if not self._pending:
            return
        fb = concat([p[0] for p in self._pending])
        service = np.concatenate([p[1] for p in self._pending])
        node = np.concatenate([p[2] for p in self._pending])
        self._pending, self._waiting = [], 0
        ns = log_time_ns(fb.t)
        if len(ns) > 1 and (ns[1:] < ns[:-1]).any():  # e.g. two adapters' clocks
            order = np.argsort(ns, kind="stable")
            fb, service, node, ns = fb.take(order), service[order], node[order], ns[order]
        payloads = frame_payloads(fb, service, node)
        self._writer.messages(np.full(len(fb), self._channel, np.uint16), ns, payloads)
        # the chunk on disk now, not in the writer thread or the file buffer: a recording
        # killed (SIGKILL, power loss of the process) keeps every chunk written before
        self._writer.drain()
        self._file.flush()
        self.frames += len(fb)

    def close(self) -> None:
        """Pending frames, metadata, summary and footer (idempotent)."""
        from cananalyze.core.version import __version__

        if self._file.closed:
            return
        try:
            self.flush()
            self._writer.metadata(
                "cananalyze",
                {"version": __version__, "source": "live recording", "frames": str(self.frames)},
            )
            self._writer.finish()
        except BaseException:
            self._writer.abort()
            raise
        finally:
            self._file.close()
