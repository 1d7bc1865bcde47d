"""Loop-back echoes in Linux cooked captures (SLL, SLL2), left out and counted.

A host that sends on can0 while it captures sees each of its frames twice: once going
out (PACKET_OUTGOING, read as FLAG_TX) and once more as received, when the controller
reports the frame sent (the echo, CAN_RAW's loop-back). The second copy is the same
frame, not a second one: read as traffic it made every SDO request a "new request after
0.0 ms" and its transfer a timeout. A received frame is an echo when an outgoing frame
of the same channel, identifier, flags, length and bytes came before it and is not yet
matched by an echo, within ECHO_WINDOW_S; outgoing frames are matched in order (first
out, first echoed). Computed on columns per batch, with the unmatched outgoing frames of
a batch's last ECHO_WINDOW_S carried into the next.
"""

from __future__ import annotations

import numpy as np

from cananalyze.core.frames import FLAG_TX, FrameBatch

# an echo follows its frame by the time it waits for the bus: microseconds idle, a few
# milliseconds behind a busy queue; half a second leaves room and stays far below the
# period at which a node repeats an identical frame that matters (heartbeat, SDO retry)
ECHO_WINDOW_S = 0.5


class EchoFilter:
    """Drops the echoes of one capture's outgoing frames (`dropped` counts them)."""

    def __init__(self) -> None:
        self.dropped = 0
        self._keys = np.zeros((0, 3), np.uint64)  # outgoing frames not yet echoed
        self._t = np.zeros(0, np.float64)

    def apply(self, fb: FrameBatch) -> FrameBatch:
        n = len(fb)
        tx = (fb.flags & FLAG_TX) != 0
        if n == 0 or not (tx.any() or self._t.size):
            return fb
        keys = np.concatenate([self._keys, _keys(fb)])
        t = np.concatenate([self._t, fb.t.astype(np.float64)])
        out = np.concatenate([np.ones(self._t.size, bool), tx])
        carried = self._t.size
        _, group = np.unique(keys, axis=0, return_inverse=True)
        group = group.reshape(-1)
        order = np.lexsort((np.arange(group.size), group))  # by group, then in log order
        g, o = group[order], out[order]
        starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
        rank = np.cumsum(np.r_[False, g[1:] != g[:-1]])  # 0.. per group, in order
        step = np.where(o, -1, 1).astype(np.int64)
        total = np.cumsum(step)
        before = np.repeat(total[starts] - step[starts], np.diff(np.r_[starts, g.size]))
        d = total - before  # received minus outgoing so far, within the group
        # a received frame is matched when an outgoing one waits: d does not rise above
        # every earlier value of its group (nor above 0); groups kept apart by an offset
        big = 2 * (g.size + 1)
        e = d + rank * big
        prior = np.maximum(np.r_[np.iinfo(np.int64).min, np.maximum.accumulate(e)[:-1]], rank * big)
        echo = ~o & (e <= prior)
        # the k-th echo of a group pairs with its k-th outgoing frame: within the window?
        outs = np.flatnonzero(o)
        first_out = np.searchsorted(g[outs], g)
        k_echo = _count_in_group(echo, starts, g.size) - 1
        at = np.flatnonzero(echo)
        pair = outs[first_out[at] + k_echo[at]]
        late = t[order][at] - t[order][pair] > ECHO_WINDOW_S
        echo[at[late]] = False
        # the outgoing frames no echo matched, of the last window, wait for the next batch
        matched = np.zeros(g.size, bool)
        matched[pair[~late]] = True
        matched[pair[late]] = True  # paired in order, even if too late: not waiting
        waiting = o & ~matched & (t[order] >= float(t[-1]) - ECHO_WINDOW_S)
        keep_rows = order[waiting]
        self._keys, self._t = keys[keep_rows], t[keep_rows]
        drop = order[echo] - carried  # echoes are received frames: all in this batch
        if not drop.size:
            return fb
        self.dropped += int(drop.size)
        keep = np.ones(n, bool)
        keep[drop] = False
        return fb.take(keep)


def _count_in_group(flag: np.ndarray, starts: np.ndarray, n: int) -> np.ndarray:
    """How many of `flag` up to and including each place, counted from its group's start."""
    c = np.cumsum(flag.astype(np.int64))
    base = c[starts] - flag[starts]
    return c - np.repeat(base, np.diff(np.r_[starts, n]))


def _keys(fb: FrameBatch) -> np.ndarray:
    """(n, 3) uint64: channel, identifier, flags but TX, length; the 8 data bytes; a hash
    of a CAN FD frame's bytes past the eighth."""
    k = np.zeros((len(fb), 3), np.uint64)
    k[:, 0] = (
        fb.can_id.astype(np.uint64)
        | ((fb.flags & ~np.uint8(FLAG_TX)).astype(np.uint64) << np.uint64(32))
        | (fb.dlc.astype(np.uint64) << np.uint64(40))
        | (fb.channel.astype(np.uint64) << np.uint64(48))
    )
    k[:, 1] = np.ascontiguousarray(fb.data).view("<u8")[:, 0]
    for row, extra in fb.long_data.items():
        k[row, 2] = hash(extra) & 0xFFFF_FFFF_FFFF_FFFF
    return k
