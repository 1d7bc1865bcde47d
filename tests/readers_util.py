"""Helpers for reader tests: run one format's read() on a file and compare with python-can."""

from __future__ import annotations

import io

import numpy as np

from cananalyze.core.errors import ProblemLog
from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
    concat,
)
from cananalyze.formats.registry import ReadContext


def run(
    read, path_or_bytes, strict: bool = False, batch_size: int = 1000, source: str | None = None
):
    """(all rows as one FrameBatch, ctx, batches) from reader ``read`` on a file or bytes."""
    if isinstance(path_or_bytes, (bytes, bytearray)):
        stream = io.BytesIO(path_or_bytes)
        name = source or "mem"
    else:
        stream = open(path_or_bytes, "rb")
        name = source or str(path_or_bytes)
    ctx = ReadContext(source=name, problems=ProblemLog(strict=strict), batch_size=batch_size)
    with stream:
        batches = list(read(stream, ctx))
    for b in batches:
        assert len(b) <= batch_size
    return concat(batches) if batches else FrameBatch.empty(), ctx, batches


def assert_same_as_python_can(
    batch: FrameBatch, messages, time_tol: float = 1e-6, channel_offset: int = 1
):
    """Every row equals python-can's Message: id, flags, data, time, channel."""
    assert len(batch) == len(messages)
    for i, m in enumerate(messages):
        where = f"row {i} (line {batch.line[i]}): {m}"
        assert batch.can_id[i] == m.arbitration_id, where
        f = int(batch.flags[i])
        if not m.is_error_frame:  # python-can leaves is_extended_id at its default there
            assert bool(f & FLAG_EXT) == m.is_extended_id, where
        assert bool(f & FLAG_RTR) == m.is_remote_frame, where
        assert bool(f & FLAG_ERR) == m.is_error_frame, where
        assert bool(f & FLAG_FD) == m.is_fd, where
        assert bool(f & FLAG_BRS) == m.bitrate_switch, where
        assert bool(f & FLAG_ESI) == m.error_state_indicator, where
        assert bool(f & FLAG_TX) == (not m.is_rx), where
        if not m.is_remote_frame and not m.is_fd and m.dlc > 8:
            # classic frame with DLC code 9..15: 8 data bytes on the bus (pcan3.trc has DLC 10)
            assert batch.payload(i) == bytes(m.data[:8]) and batch.dlc[i] == 8, where
        elif not m.is_remote_frame:
            assert batch.payload(i) == bytes(m.data), where
            assert batch.dlc[i] == len(m.data), where
        else:
            assert batch.dlc[i] == min(m.dlc, 64), where
        assert abs(batch.t[i] - m.timestamp) <= time_tol, (where, batch.t[i])
        if channel_offset is not None and m.channel is not None:
            assert batch.channel_name(i) == str(m.channel + channel_offset), where
    assert np.all(batch.line >= 1)
