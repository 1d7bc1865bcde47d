"""python-can's writers for the formats it writes as their reference (ASC, BLF): frames
as python-can Messages, and the file finished as python-can finishes it."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX, FrameBatch


def to_messages(batch: FrameBatch) -> Iterator:
    """python-can Messages for a (small) batch: only for python-can's writers and buses."""
    import can

    chans = batch.channels or ("can0",)
    for i in range(len(batch)):
        fl = int(batch.flags[i])
        yield can.Message(
            timestamp=float(batch.t[i]),
            arbitration_id=int(batch.can_id[i]),
            is_extended_id=bool(fl & FLAG_EXT),
            is_remote_frame=bool(fl & FLAG_RTR),
            is_error_frame=bool(fl & FLAG_ERR),
            is_fd=bool(fl & FLAG_FD),
            bitrate_switch=bool(fl & 0x10),
            error_state_indicator=bool(fl & 0x20),
            is_rx=not fl & FLAG_TX,
            dlc=int(batch.dlc[i]),
            data=b"" if fl & FLAG_RTR else batch.payload(i),
            channel=chans[int(batch.channel[i])] if int(batch.channel[i]) < len(chans) else 0,
        )


class PycanWriter:
    """A python-can writer (`make(path)`) fed a batch at a time."""

    def __init__(self, path: Path, make) -> None:
        self.path = Path(path)
        self.start: float | None = None  # the first frame's time
        self._writer = make(str(path))

    def write(self, batch: FrameBatch) -> None:
        if not len(batch):
            return
        if self.start is None:
            self.start = float(batch.t[0])
        for msg in to_messages(batch):
            self._writer.on_message_received(msg)

    def flush(self) -> None:
        if self._writer is not None:
            self._writer.file.flush()

    def close(self) -> None:
        """Finish the file (idempotent)."""
        if self._writer is not None:
            self._writer.stop()
            self._writer = None
