"""CiA 402: a drive entering fault (fault reaction active or fault), with the EMCY it sent.

The EMCY a drive sends with its fault is looked for from `emcy_window_ms` before the
statusword shows the fault to as long after it within the same batch (the EMCY usually
comes first, since the statusword waits for the next TPDO or poll). In a log without
times the window is counted in frames: the node's last EMCY raised before (and not
reset since), or one within UNTIMED_FRAMES frames after.
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.decode.drive_tracker import RESET, STATE
from cananalyze.devices import cia402
from cananalyze.protocol.emcy import MIN_BYTES, error_text
from cananalyze.protocol.services import Service

_FAULTS = (cia402.FAULT_REACTION, cia402.FAULT)
# a log without times: an EMCY this many frames after the statusword still goes with it
# (a drive sends it at once; the statusword's next TPDO or poll may come first)
UNTIMED_FRAMES = 20


class DriveFaultRule(Rule):
    name = "drive_fault"
    severity = "error"
    timing = False  # judged by the order of the statuswords: kept on logs without times
    why = (
        "The drive stopped on a fault: read its EMCY code and 0x603F (error code), fix the "
        "cause, then a fault reset (controlword bit 7) returns it to switch on disabled."
    )

    def __init__(self, emcy_window_ms: float = 1000.0, **kw) -> None:
        super().__init__(**kw)
        self.window = float(emcy_window_ms) / 1000.0
        self.last: dict[int, int] = {}
        self.emcy: dict[int, tuple[float, int]] = {}  # node -> last EMCY raised (t, code)

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        rows = ctx.rows(Service.EMCY)
        fb = b.frames
        rows = rows[fb.dlc[rows] >= MIN_BYTES]
        codes = fb.data[rows, 0].astype(np.int64) | (fb.data[rows, 1].astype(np.int64) << 8)
        nodes = b.node[rows]
        # as tuples only for a batch with drive changes to pair them with
        emcy = (
            list(zip(rows.tolist(), nodes.tolist(), codes.tolist(), strict=True)) if b.drive else []
        )
        k = 0
        for c in b.drive:
            while k < len(emcy) and emcy[k][0] <= c.row:  # the EMCYs before this change
                self._saw(fb, *emcy[k])
                k += 1
            if c.kind == RESET:
                self.last.pop(c.node, None)
                continue
            if c.kind != STATE:
                continue
            before = self.last.get(c.node)
            self.last[c.node] = c.code
            self.subjects.add(c.node)
            if c.code not in _FAULTS or before in _FAULTS:
                continue
            sent = self.emcy.get(c.node)
            if sent is not None and ctx.timed and c.t - sent[0] > self.window:
                sent = None
            if sent is None:
                sent = next(
                    (
                        (float(fb.t[r]), code)
                        for r, n, code in emcy[k:]
                        if n == c.node
                        and code
                        and (
                            float(fb.t[r]) - c.t <= self.window
                            if ctx.timed
                            else r - c.row <= UNTIMED_FRAMES
                        )
                    ),
                    None,
                )
            with_emcy = (
                f" with EMCY {error_text(sent[1])} at {ctx.rel(sent[0])}"
                if sent
                else " (no EMCY from the node around it)"
            )
            self.emit(
                c.t,
                c.node,
                c.cob_id or None,
                f"drive entered {cia402.STATE_NAMES[c.code]} (statusword 0x{c.word:04X})"
                + with_emcy,
                f"0x{sent[1]:04X}" if sent else cia402.STATE_NAMES[c.code],
                "no fault",
                row=c.row,
            )
        self._saw_last(fb, rows[k:], nodes[k:], codes[k:])

    def _saw_last(self, fb, rows: np.ndarray, nodes: np.ndarray, codes: np.ndarray) -> None:
        """`_saw` of each EMCY in order, as columns: each node's last EMCY raised is kept."""
        if codes.size == 0:
            return
        order = np.arange(codes.size)[::-1]  # latest first: np.unique's first is the last
        node_ids, at = np.unique(nodes[order], return_index=True)
        last = order[at]
        for n, r, code in zip(
            node_ids.tolist(), rows[last].tolist(), codes[last].tolist(), strict=True
        ):
            self._saw(fb, r, n, code)

    def _saw(self, fb, row: int, node: int, code: int) -> None:
        """A node's EMCY: raised (kept to pair with a fault) or reset (code 0: none)."""
        if code:
            self.emcy[node] = (float(fb.t[row]), code)
        else:
            self.emcy.pop(node, None)
