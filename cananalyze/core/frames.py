"""FrameBatch: the columnar unit every part of cananalyze agrees on.

Logs can hold tens of millions of frames, so frames never travel as one Python
object each. A batch holds a few thousand to a million frames as numpy columns;
readers produce batches, the decoder annotates them, outputs consume them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

# Bits of FrameBatch.flags.
FLAG_EXT = 0x01  # 29-bit identifier
FLAG_RTR = 0x02  # remote transmission request
FLAG_ERR = 0x04  # CAN error frame
FLAG_FD = 0x08  # CAN FD frame
FLAG_BRS = 0x10  # CAN FD bit-rate switch
FLAG_ESI = 0x20  # CAN FD error state indicator
FLAG_TX = 0x40  # sent by the logging node (direction flag of the log), else received
# the data bytes were rebuilt by the reader from the log's text, not captured (Sevcon DVT
# dumps give EMCY frames as decoded text only): text output marks the frame with
# RECONSTRUCTED_MARK, JSONL with "reconstructed": true
FLAG_RECONSTRUCTED = 0x80
RECONSTRUCTED_MARK = "(reconstructed)"

# FrameBatch.channel is a uint16 index into the channel names: a log naming more channels
# than that (hostile, or a tool writing one name per frame) keeps every frame, the ones
# beyond the limit under one shared name
MAX_CHANNELS = 1 << 16
OTHER_CHANNELS = "(other channels)"
# buses decoded apart (pipeline.Decoder, the nodes table); the channels past these share one
MAX_BUSES = 64


def channel_index(names: list[str], index: dict[str, int], name: str) -> int:
    """Index of `name` in a reader's channel table, adding it on first sight (bounded)."""
    i = index.get(name)
    if i is None:
        if len(names) < MAX_CHANNELS - 1:
            i = index[name] = len(names)
            names.append(name)
        else:
            if len(names) < MAX_CHANNELS:
                names.append(OTHER_CHANNELS)
            i = MAX_CHANNELS - 1
    return i


EMPTY_CHANNELS: tuple[str, ...] = ()


@dataclass
class FrameBatch:
    """Columns of n frames.

    t        float64 seconds; absolute (Unix epoch) when the log says so, else relative.
    can_id   uint32 identifier without flag bits.
    flags    uint8, FLAG_* bits.
    dlc      uint8 number of data bytes (0..64, not the DLC code).
    data     (n, 8) uint8, the first 8 data bytes, zero padded.
    channel  uint16 index into ``channels``.
    line     int64 1-based line (text logs) or record number (binary logs), for messages.
    long_data  row -> full payload, only for CAN FD rows with more than 8 bytes (rare).
    """

    t: np.ndarray
    can_id: np.ndarray
    flags: np.ndarray
    dlc: np.ndarray
    data: np.ndarray
    channel: np.ndarray
    line: np.ndarray
    channels: tuple[str, ...] = EMPTY_CHANNELS
    long_data: dict[int, bytes] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @classmethod
    def empty(cls, channels: tuple[str, ...] = EMPTY_CHANNELS) -> FrameBatch:
        return cls.allocate(0, channels)

    @classmethod
    def allocate(cls, n: int, channels: tuple[str, ...] = EMPTY_CHANNELS) -> FrameBatch:
        """Zeroed columns for n frames, for readers that fill in place."""
        return cls(
            t=np.zeros(n, np.float64),
            can_id=np.zeros(n, np.uint32),
            flags=np.zeros(n, np.uint8),
            dlc=np.zeros(n, np.uint8),
            data=np.zeros((n, 8), np.uint8),
            channel=np.zeros(n, np.uint16),
            line=np.zeros(n, np.int64),
            channels=channels,
        )

    def payload(self, i: int) -> bytes:
        """Data bytes of row i (Python-level access for rare, stateful traffic)."""
        long = self.long_data.get(i)
        if long is not None:
            return long
        return self.data[i, : int(self.dlc[i])].tobytes()

    def take(self, idx: np.ndarray | slice) -> FrameBatch:
        """Rows selected by a boolean mask, index array or slice (columns copied or viewed)."""
        if not isinstance(idx, slice):
            idx = np.asarray(idx)
        long = {}
        if self.long_data:  # a slice needs no index array otherwise
            if isinstance(idx, slice):
                rows = np.arange(len(self))[idx]
            else:
                rows = np.flatnonzero(idx) if idx.dtype == bool else idx
            where = {old: new for new, old in enumerate(rows.tolist())}
            long = {where[k]: v for k, v in self.long_data.items() if k in where}
        return FrameBatch(
            t=self.t[idx],
            can_id=self.can_id[idx],
            flags=self.flags[idx],
            dlc=self.dlc[idx],
            data=self.data[idx],
            channel=self.channel[idx],
            line=self.line[idx],
            channels=self.channels,
            long_data=long,
        )

    def channel_name(self, i: int) -> str:
        return self.channel_label(int(self.channel[i]))

    def channel_label(self, c: int) -> str:
        """The interface name of channel index c (its number when the log named none)."""
        return self.channels[c] if c < len(self.channels) else str(c)


def concat(batches: Iterable[FrameBatch]) -> FrameBatch:
    """Join batches that share one channel table (readers keep channel indices stable)."""
    batches = [b for b in batches]
    if not batches:
        return FrameBatch.empty()
    channels = max((b.channels for b in batches), key=len)
    long: dict[int, bytes] = {}
    offset = 0
    for b in batches:
        for k, v in b.long_data.items():
            long[k + offset] = v
        offset += len(b)
    return FrameBatch(
        t=np.concatenate([b.t for b in batches]),
        can_id=np.concatenate([b.can_id for b in batches]),
        flags=np.concatenate([b.flags for b in batches]),
        dlc=np.concatenate([b.dlc for b in batches]),
        data=np.concatenate([b.data for b in batches]),
        channel=np.concatenate([b.channel for b in batches]),
        line=np.concatenate([b.line for b in batches]),
        channels=channels,
        long_data=long,
    )


def from_rows(
    rows: Iterable[tuple[float, int, bytes]] | Iterable[tuple],
    channels: tuple[str, ...] = ("can0",),
) -> FrameBatch:
    """Build a batch from (t, can_id, data[, flags[, channel]]) tuples.

    For tests, samples and the simulator: small inputs only, never a log's bulk path.
    """
    rows = list(rows)
    b = FrameBatch.allocate(len(rows), channels)
    for i, row in enumerate(rows):
        t, can_id, data = row[0], row[1], bytes(row[2])
        flags = row[3] if len(row) > 3 else 0
        chan = row[4] if len(row) > 4 else 0
        if can_id > 0x7FF:
            flags |= FLAG_EXT
        set_row(b, i, t, can_id, flags, data, chan, i + 1)
    return b


def set_row(
    b: FrameBatch, i: int, t: float, can_id: int, flags: int, payload: bytes, chan: int, line: int
) -> None:
    """Fill row i of a batch from Python values (rare paths: line parsers, tests, samples)."""
    b.t[i] = t
    b.can_id[i] = can_id
    b.flags[i] = flags
    b.dlc[i] = len(payload)
    b.data[i, : min(8, len(payload))] = np.frombuffer(payload[:8], np.uint8)
    if len(payload) > 8:
        b.long_data[i] = payload
    b.channel[i] = chan
    b.line[i] = line
