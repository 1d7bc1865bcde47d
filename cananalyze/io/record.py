"""FrameRecorder: the raw frames of a live session, saved as candump, ASC, BLF or MCAP.

Log formats go through python-can's writers (its `can.Logger` picks one by suffix),
the reference implementations of those formats. MCAP has no python-can writer: raw
frames go on a `/can/frames` topic as JSON messages (a jsonschema is registered, so
Foxglove shows the fields) through the `mcap` package. `close()` finalises the file
(BLF header counts, MCAP summary), which is what keeps a recording valid when a live
session is interrupted.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import UsageError
from ..frames import FLAG_BRS, FLAG_ERR, FLAG_ESI, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX, FrameBatch

LOG_SUFFIXES = (".log", ".asc", ".blf")
MCAP_TOPIC = "/can/frames"
MCAP_SCHEMA = {
    "type": "object",
    "title": "cananalyze.CanFrame",
    "properties": {
        "timestamp": {"type": "number", "description": "seconds since the Unix epoch"},
        "channel": {"type": "string"},
        "id": {"type": "integer"},
        "extended": {"type": "boolean"},
        "remote": {"type": "boolean"},
        "error": {"type": "boolean"},
        "fd": {"type": "boolean"},
        "brs": {"type": "boolean"},
        "esi": {"type": "boolean"},
        "tx": {"type": "boolean"},
        "dlc": {"type": "integer", "description": "number of data bytes"},
        "data": {"type": "string", "description": "payload as hex"},
    },
}


class FrameRecorder:
    """Write every FrameBatch it is given to `path`; the format comes from the suffix."""

    @staticmethod
    def check_suffix(path: str | Path) -> None:
        suffix = Path(path).suffix.lower()
        if suffix != ".mcap" and suffix not in LOG_SUFFIXES:
            raise UsageError(f"--record {path}: use a .log (candump), .asc, .blf or .mcap file")

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.frames = 0
        self.check_suffix(path)
        self._mcap = self.path.suffix.lower() == ".mcap"
        try:
            if self._mcap:
                from mcap.writer import Writer

                self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
                self._writer = Writer(self._file)
                self._writer.start(profile="", library="cananalyze")
                schema = self._writer.register_schema(
                    "cananalyze.CanFrame", "jsonschema", json.dumps(MCAP_SCHEMA).encode()
                )
                self._channel = self._writer.register_channel(MCAP_TOPIC, "json", schema)
            else:
                import can

                self._logger = can.Logger(str(self.path))
        except OSError as exc:
            raise UsageError(f"--record {path}: cannot write: {exc.strerror or exc}") from None

    def write(self, batch: FrameBatch) -> None:
        if not len(batch):
            return
        if self._mcap:
            self._write_mcap(batch)
        else:
            from .logfile import to_messages

            for msg in to_messages(batch):
                self._logger.on_message_received(msg)
        self.frames += len(batch)

    def _write_mcap(self, batch: FrameBatch) -> None:
        ts = batch.t.tolist()
        ids = batch.can_id.tolist()
        flags = batch.flags.tolist()
        chans = batch.channels or ("can0",)
        for i in range(len(batch)):
            fl = flags[i]
            payload = b"" if fl & FLAG_RTR else batch.payload(i)
            ch = int(batch.channel[i])
            rec = {
                "timestamp": ts[i],
                "channel": chans[ch] if ch < len(chans) else str(ch),
                "id": ids[i],
                "extended": bool(fl & FLAG_EXT),
                "remote": bool(fl & FLAG_RTR),
                "error": bool(fl & FLAG_ERR),
                "fd": bool(fl & FLAG_FD),
                "brs": bool(fl & FLAG_BRS),
                "esi": bool(fl & FLAG_ESI),
                "tx": bool(fl & FLAG_TX),
                "dlc": int(batch.dlc[i]),
                "data": payload.hex(),
            }
            ns = int(round(ts[i] * 1e9))
            self._writer.add_message(
                self._channel, log_time=ns, data=json.dumps(rec).encode(), publish_time=ns
            )

    def close(self) -> None:
        """Finalise the file (idempotent)."""
        if self._mcap:
            if self._file.closed:
                return
            try:
                self._writer.finish()
            finally:
                self._file.close()
        elif self._logger is not None:
            self._logger.stop()
            self._logger = None
