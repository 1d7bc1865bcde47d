"""Bus load: nominal bits per frame and their sum over time windows, as columns.

Counts start of frame to end of frame plus the 3-bit interframe space, without
stuff bits, so it is a lower bound (stuffing adds up to about 20 % on real traffic).
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR


def frame_bits(flags: np.ndarray, dlc: np.ndarray) -> np.ndarray:
    """Nominal bits on the wire of each frame (int64)."""
    ext = (flags & FLAG_EXT) != 0
    rtr = (flags & FLAG_RTR) != 0
    payload = np.where(rtr, 0, dlc.astype(np.int64))
    bits = np.where(ext, 67, 47) + 8 * payload
    bits = np.where((flags & FLAG_ERR) != 0, 20, bits)  # error flag + delimiter
    return np.where((flags & FLAG_FD) != 0, np.where(ext, 88, 69) + 8 * payload, bits)


_SHAPE_FLAGS = FLAG_EXT | FLAG_RTR | FLAG_ERR | FLAG_FD  # the flags frame_bits reads
assert _SHAPE_FLAGS < 16
# frame_bits of every (flags & _SHAPE_FLAGS, dlc) pair, at index flags << 8 | dlc
_BITS_OF_SHAPE = frame_bits(
    (np.arange(16 * 256) >> 8).astype(np.uint8), (np.arange(16 * 256) & 0xFF).astype(np.uint8)
)


def bits_per_channel(flags: np.ndarray, dlc: np.ndarray, channel: np.ndarray):
    """(frames, nominal bits) per channel index, int64 arrays as long as the highest
    channel + 1: frame_bits summed, from a count of each frame shape (flags, dlc) per
    channel instead of the bits of every frame (a third of `decode --summary`'s sink)."""
    frames = np.bincount(channel)
    shape = (flags & _SHAPE_FLAGS).astype(np.intp) << 8
    shape |= dlc
    if frames.size == 1:
        counts = np.bincount(shape, minlength=_BITS_OF_SHAPE.size)[None, :]
    elif frames.size <= 64:
        shape += channel.astype(np.intp) * _BITS_OF_SHAPE.size
        counts = np.bincount(shape, minlength=frames.size * _BITS_OF_SHAPE.size)
        counts = counts.reshape(frames.size, _BITS_OF_SHAPE.size)
    else:  # many channels: the bits of every frame
        bits = np.bincount(channel, weights=frame_bits(flags, dlc)).astype(np.int64)
        return frames, bits
    return frames, counts @ _BITS_OF_SHAPE


def bits_by_channel(fb) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each channel's frame times and nominal bits, by channel name: each bus's load is
    its own (two buses summed could read over 100 %)."""
    if not len(fb):
        return {}
    bits = frame_bits(fb.flags, fb.dlc)
    if len(fb.channels) <= 1:
        return {fb.channel_label(int(fb.channel[0])): (fb.t, bits)}
    out = {}
    for c in np.unique(fb.channel).tolist():
        mine = fb.channel == c
        out[fb.channel_label(c)] = (fb.t[mine], bits[mine])
    return out


def load_series(
    t: np.ndarray, bits: np.ndarray, window: float = 0.1, bitrate: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(window start times, bits/s or percent of bitrate) over fixed windows.

    Windows are aligned to the first frame. The last, partial window is scaled by
    its own length (up to the last frame) so a log's tail does not look idle; a
    tail shorter than half a window joins the window before it, because scaling a
    few milliseconds that end on a burst (SYNC and its PDOs) showed a spike of
    several times the real load at the end of every plot.
    """
    if t.size == 0:
        return np.zeros(0), np.zeros(0)
    t0 = float(t[0])
    idx = np.floor((t - t0) / window).astype(np.int64)
    lo = int(idx.min())  # below 0 when times went back before the first frame's
    idx -= lo
    sums = np.bincount(idx, weights=bits, minlength=int(idx.max()) + 1)
    return load_windows(sums, t0 + lo * window, float(t[-1]), window, bitrate)


def load_windows(
    sums: np.ndarray, t0: float, t_last: float, window: float, bitrate: int | None
) -> tuple[np.ndarray, np.ndarray]:
    """`load_series` from bits already summed per window (sums[0] starts at t0); t_last
    is the last frame's time. The streaming export sums batch by batch."""
    starts = t0 + np.arange(sums.size) * window
    width = np.full(sums.size, window)
    width[-1] = max(t_last - starts[-1], window / 1000)
    if sums.size > 1 and width[-1] < window / 2:
        sums[-2] += sums[-1]
        width[-2] += width[-1]
        sums, width, starts = sums[:-1], width[:-1], starts[:-1]
    per_s = sums / width
    if bitrate:
        return starts, per_s / bitrate * 100.0
    return starts, per_s


def bits_per_node(flags: np.ndarray, dlc: np.ndarray, node: np.ndarray, sent: np.ndarray):
    """(frames, nominal bits) per node-ID 0..127 of the frames each node sent itself
    (`sent`: a row mask, decode/senders.SENT of its service), int64 arrays of 128.

    Every row goes to a bin (a frame no node sent, bin 0, dropped), not a masked copy
    of the rows; classic standard frames, nearly all of a CANopen bus, in one integer
    bincount of (node, length): a third of the masked-copy version's CPU."""
    if node.size and not (int(node.min()) >= -1 and int(node.max()) <= 127):
        keep = (node >= -1) & (node <= 127)  # not a node-ID: not counted
        flags, dlc, node, sent = flags[keep], dlc[keep], node[keep], sent[keep]
    classic = not (flags & _SHAPE_FLAGS).any() and int(dlc.max(initial=0)) < 16
    # classic: every bin (node + 1) << 4 | dlc is below 2064, so 16-bit bins (node -1
    # wraps to 0 with the + 1): a quarter of the memory the intp passes go over
    at = node.astype(np.uint16 if classic else np.intp)
    at += 1
    at *= sent
    if classic:
        at <<= 4
        at |= dlc
        return bits_of_lengths(np.bincount(at, minlength=129 * 16).reshape(129, 16))
    frames = np.bincount(at, minlength=129)[1:]
    shape = (flags & _SHAPE_FLAGS).astype(np.intp) << 8
    shape |= dlc
    bits = np.bincount(at, weights=_BITS_OF_SHAPE[shape], minlength=129)[1:]
    return frames, bits.astype(np.int64)


def bits_of_lengths(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`bits_per_node` from counts[node + 1, dlc] (129 x 16) of classic standard data frames
    the nodes sent (row 0, no node, dropped): records.sender_shapes summed over the
    services a node sends."""
    counts = counts[1:]
    return counts.sum(axis=1), counts @ _BITS_OF_SHAPE[:16]


# back to back: a frame that ends within its own time on the wire (nominal bits, up to a
# fifth more for stuff bits) plus a timestamp's jitter after the one before it ended
STUFF = 1.2
JITTER_S = 50e-6


class Bursts:
    """The longest run of frames back to back on one bus (no idle bus between them),
    followed batch by batch: `add(t, bits)` with each frame's end time and nominal bits."""

    def __init__(self, bitrate: int) -> None:
        self.bitrate = bitrate
        self.last_t: float | None = None
        self.run = 0  # frames in the burst that ends at the last frame
        self.start: float | None = None  # its first frame's time
        self.longest = 0
        self.t_start: float | None = None
        self.t_end: float | None = None

    def add(self, t: np.ndarray, bits: np.ndarray) -> None:
        n = t.size
        if n == 0:
            return
        prev = np.empty(n)
        prev[0] = -np.inf if self.last_t is None else self.last_t
        prev[1:] = t[:-1]
        joins = (t - prev) <= bits / self.bitrate * STUFF + JITTER_S
        idx = np.arange(n)
        cut = np.maximum.accumulate(np.where(joins, -1, idx))  # the burst's first row
        run = np.where(cut >= 0, idx - cut + 1, self.run + idx + 1)
        k = int(np.argmax(run))
        starts = t[np.maximum(cut, 0)]
        if int(run[k]) > self.longest:
            self.longest = int(run[k])
            self.t_start = float(starts[k]) if cut[k] >= 0 else self.start
            self.t_end = float(t[k])
        self.start = float(starts[-1]) if cut[-1] >= 0 else self.start
        self.run = int(run[-1])
        self.last_t = float(t[-1])

    def record(self) -> dict | None:
        """{frames, t_start, t_end} of the longest burst (None: no frame)."""
        if not self.longest:
            return None
        return {"frames": self.longest, "t_start": self.t_start, "t_end": self.t_end}
