"""Writing frames back out as logs: candump (fast, columnar), ASC and BLF (python-can).

Used for samples, benchmark logs and `live --record`. python-can's ASC/BLF
writers are the reference implementations of those formats, so they are used
as they are; candump is written in bulk because benchmark logs run to 10M lines.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cananalyze.core.atomic import atomic_path
from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX, FrameBatch

_HEX2 = np.array([f"{i:02X}" for i in range(256)])


def candump_lines(batch: FrameBatch) -> list[str]:
    """`(t) ch id#data` lines of a batch (candump -l format)."""
    n = len(batch)
    if n == 0:
        return []
    t = np.char.mod("%.6f", batch.t)
    ids = batch.can_id
    ext = (batch.flags & (FLAG_EXT | FLAG_ERR)) != 0
    id_txt = np.where(
        ext,
        np.char.mod(
            "%08X", ids | np.where((batch.flags & FLAG_ERR) != 0, 0x20000000, 0).astype(np.uint32)
        ),
        np.char.mod("%03X", ids),
    )
    out = []
    hexed = _HEX2[batch.data]
    chans = batch.channels or ("can0",)
    for i in range(n):
        fl = int(batch.flags[i])
        dlc = int(batch.dlc[i])
        if fl & FLAG_RTR:
            body = "R" if dlc == 0 else f"R{dlc}"
        elif fl & FLAG_FD:
            payload = batch.payload(i)
            body = f"#{(1 if fl & 0x10 else 0) | (2 if fl & 0x20 else 0):X}" + payload.hex().upper()
        else:
            body = "".join(hexed[i, :dlc])
        ch = chans[int(batch.channel[i])] if int(batch.channel[i]) < len(chans) else "can0"
        line = f"({t[i]}) {ch} {id_txt[i]}#{body}"
        if fl & FLAG_TX:
            line += " T"
        out.append(line)
    return out


def _digits(values: np.ndarray, width: int) -> np.ndarray:
    """(n, width) ASCII digits of non-negative integers, zero padded."""
    out = np.empty((values.size, width), np.uint8)
    v = values.astype(np.int64).copy()
    for j in range(width - 1, -1, -1):
        out[:, j] = 48 + v % 10
        v //= 10
    return out


_HEXCHARS = np.frombuffer(b"0123456789ABCDEF", np.uint8)
_PAD = 0


def candump_bytes(batch: FrameBatch) -> bytes:
    """candump -l text of a batch of classic frames, built as one byte matrix.

    Every line is laid out at fixed width with pad bytes, then the pads are
    dropped in one boolean selection: no Python per frame.
    """
    n = len(batch)
    if n == 0:
        return b""
    chans = batch.channels or ("can0",)
    if len(chans) > 1 or (batch.flags & (FLAG_FD | FLAG_ERR)).any() or (batch.t < 0).any():
        return ("\n".join(candump_lines(batch)) + "\n").encode("ascii")
    us = np.round(batch.t * 1e6).astype(np.int64)
    sec, frac = np.divmod(us, 1_000_000)
    sec_w = max(1, len(str(int(sec.max()))))
    ch = chans[0].encode("ascii")
    ext = (batch.flags & FLAG_EXT) != 0
    rtr = (batch.flags & FLAG_RTR) != 0
    tx = (batch.flags & FLAG_TX) != 0
    parts = [
        np.full((n, 1), ord("("), np.uint8),
        _digits(sec, sec_w),
        np.full((n, 1), ord("."), np.uint8),
        _digits(frac, 6),
        np.frombuffer(b") " + ch + b" ", np.uint8)[None, :].repeat(n, 0),
    ]
    ident = np.empty((n, 8), np.uint8)
    for j in range(8):
        ident[:, j] = _HEXCHARS[(batch.can_id >> (4 * (7 - j))) & 0xF]
    ident[~ext, :5] = _PAD  # 3-digit standard identifiers
    parts.append(ident)
    parts.append(np.full((n, 1), ord("#"), np.uint8))
    data = np.empty((n, 16), np.uint8)
    data[:, 0::2] = _HEXCHARS[batch.data >> 4]
    data[:, 1::2] = _HEXCHARS[batch.data & 0xF]
    data[np.arange(16) >= 2 * batch.dlc[:, None].astype(np.int64)] = _PAD
    data[rtr] = _PAD
    data[rtr, 0] = ord("R")
    rtr_len = rtr & (batch.dlc > 0)
    data[rtr_len, 1] = 48 + batch.dlc[rtr_len]
    parts.append(data)
    tail = np.full((n, 3), _PAD, np.uint8)
    tail[tx, 0] = ord(" ")
    tail[tx, 1] = ord("T")
    tail[:, 2] = ord("\n")
    parts.append(tail)
    mat = np.concatenate(parts, axis=1)
    return mat[mat != _PAD].tobytes()


def to_messages(batch: FrameBatch):
    """python-can Messages for a (small) batch: only for the ASC/BLF writers."""
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


def _set_asc_date(path: Path, start: float) -> None:
    """python-can stamps the ASC `date` line with the wall clock; use the log's start.

    Keeps written files reproducible and the header's absolute time meaningful.
    """
    from datetime import datetime

    import can

    lines = path.read_text(encoding="ascii").split("\n")
    if lines and lines[0].startswith("date "):
        stamp = can.ASCWriter._format_header_datetime(can.ASCWriter, datetime.fromtimestamp(start))  # type: ignore[arg-type]
        lines[0] = f"date {stamp}"
        path.write_text("\n".join(lines), encoding="ascii")


# The log formats we write, by suffix: the one table `write_log`, `simulate --to` and
# `live --record` (formats/record.py) read. candump is ours (bulk, as candump -l writes it);
# ASC and BLF are python-can's writers, the reference implementations of those formats.
WRITTEN = {".log": "candump", ".asc": "asc", ".blf": "blf"}


class LogWriter:
    """Appends batches to a candump, ASC or BLF file, the format from its suffix."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.format = WRITTEN.get(self.path.suffix.lower())
        if self.format is None:
            raise ValueError(f"{path}: write .log, .asc or .blf")
        self._start: float | None = None
        if self.format == "candump":
            self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
            self._writer = None
        else:
            import can

            self._file = None
            self._writer = (can.ASCWriter if self.format == "asc" else can.BLFWriter)(str(path))

    def write(self, batch: FrameBatch) -> None:
        if not len(batch):
            return
        if self._start is None:
            self._start = float(batch.t[0])
        if self._file is not None:
            self._file.write(candump_bytes(batch))
        else:
            for msg in to_messages(batch):
                self._writer.on_message_received(msg)

    def flush(self) -> None:
        """Everything written so far onto the file (the OS's), so that a process killed
        after it (SIGKILL) leaves a readable file holding those frames: `live --record`
        calls it every second."""
        if self._file is not None:
            self._file.flush()
        elif self._writer is not None:
            if self.format == "blf":
                # python-can's BLFWriter keeps frames until a 128 KiB container is full and
                # has no public flush: its _flush writes one container of what it holds
                while self._writer._buffer_size:
                    self._writer._flush()
            self._writer.file.flush()

    def close(self) -> None:
        """Finish the file (idempotent); an ASC file's header date is its first frame's."""
        if self._file is not None:
            self._file.close()
            self._file = None
        elif self._writer is not None:
            self._writer.stop()
            self._writer = None
            if self.format == "asc" and self._start is not None:
                _set_asc_date(self.path, self._start)


def write_log(batch: FrameBatch, path: str | Path) -> None:
    """Write a batch as candump (.log), ASC (.asc) or BLF (.blf), atomically (core/atomic)."""
    path = Path(path)
    if path.suffix.lower() not in WRITTEN:
        raise ValueError(f"{path}: write .log, .asc or .blf")
    with atomic_path(path) as tmp:  # keeps the suffix: the format comes from it
        writer = LogWriter(tmp)
        try:
            writer.write(batch)
        finally:
            writer.close()
