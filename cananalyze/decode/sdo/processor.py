"""SdoProcessor: runs the SDO tracker over the SDO rows of each batch.

SDO traffic is rare and stateful, so this is one of the places where per-frame
Python is right. Rows on the default channels are found by the classifier;
extra channels learnt from 0x1200-0x12FF writes are found by the tracker.
Expedited request/response pairs on idle channels, the bulk of a polled bus,
and stray initiate responses on idle channels take the columnar shortcut in
`fastpath` (same records and notes, ~20x less time); `fast=False` sends every
frame through the tracker.
"""

from __future__ import annotations

import bisect
from typing import Protocol

import numpy as np

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR
from cananalyze.core.records import DecodedBatch
from cananalyze.core.sdo_records import FastPart, RecordColumns
from cananalyze.decode.node_tally import IDENTITY, IDENTITY_INDEX
from cananalyze.decode.sdo import fastpath, roles
from cananalyze.decode.sdo.lazynotes import LazyNotes
from cananalyze.decode.sdo.tracker import SdoTracker
from cananalyze.decode.sdo.usdo import UsdoTracker
from cananalyze.protocol import sdo
from cananalyze.protocol.services import Service

_ENDED = ("ok", "abort")  # by "aborted": no numpy string array per batch


class Identifier(Protocol):
    """What names a node's device from its identity reads (the network model)."""

    def may_identify(self, node: int, index: int, subindex: int) -> bool: ...

    def identify_now(self, row: int, rec: dict) -> None: ...


class SdoProcessor:
    def __init__(
        self,
        tracker: SdoTracker | None = None,
        fast: bool = True,
        identifier: Identifier | None = None,
        usdo: UsdoTracker | None = None,
        fd_nodes: frozenset[int] | bool = frozenset(),
    ) -> None:
        self.tracker = tracker or SdoTracker()
        # CiA 1301 (CANopen FD): FD frames on the SDO COB-IDs are USDO, and every frame on
        # those of a node (or, `fd_nodes` True, of the whole network) marked CANopen FD
        self.usdo = usdo or UsdoTracker(self.tracker.timeout, self.tracker.object_info)
        self.fd_nodes = fd_nodes
        self.fast = fast
        # told of each identity read as it ends, so that the transfers after it are named
        self.identifier = identifier
        self._offset = 0  # frames before the current batch, so refs are global

    def _rows(self, batch: DecodedBatch) -> np.ndarray:
        svc = batch.service
        # SDO_RESPONSE follows SDO_REQUEST: one subtraction (wrapping in uint8) and a compare
        since = (svc - np.uint8(Service.SDO_REQUEST)).astype(np.uint8, copy=False)
        is_sdo = since <= np.uint8(1)
        extra = self.tracker.extra_cob_ids()
        if extra:
            plain = (batch.frames.flags & (FLAG_EXT | FLAG_ERR | FLAG_RTR)) == 0
            on_extra = np.isin(batch.frames.can_id, np.fromiter(extra, np.uint32)) & plain
            for row in np.flatnonzero(on_extra & ~is_sdo):
                node, is_request = self.tracker.channel_of(int(batch.frames.can_id[row]))
                batch.service[row] = Service.SDO_REQUEST if is_request else Service.SDO_RESPONSE
                batch.node[row] = node
                batch.pdo[row] = 0
            is_sdo |= on_extra
        rows = np.flatnonzero(is_sdo & ((batch.frames.flags & FLAG_RTR) == 0))
        if not len(rows):
            return rows
        fd = (batch.frames.flags[rows] & FLAG_FD) != 0
        if self.fd_nodes:
            fd |= self._fd_marked(batch, rows)
        if fd.any():
            self._usdo_rows = rows[fd]
            for row in self._usdo_rows.tolist():
                resp = (int(batch.frames.can_id[row]) & 0x780) == 0x580
                batch.service[row] = Service.USDO_RESPONSE if resp else Service.USDO_REQUEST
                dest = int(batch.frames.data[row, 0])
                if not resp and 1 <= dest <= 127:  # a frame's node: the server, as for the SDO
                    batch.node[row] = dest
            rows = rows[~fd]
        return rows

    def _fd_marked(self, batch: DecodedBatch, rows: np.ndarray) -> np.ndarray:
        """Rows on the SDO COB-IDs of the nodes marked CANopen FD (all of them: True)."""
        if self.fd_nodes is True:
            return np.ones(len(rows), bool)
        cob = batch.frames.can_id[rows]
        return np.isin(cob & 0x7F, np.fromiter(self.fd_nodes, np.uint32)) & (
            (cob & 0x780 == 0x580) | (cob & 0x780 == 0x600)
        )

    def _feed_usdo(self, batch: DecodedBatch, row: int) -> None:
        """One USDO frame through the USDO tracker (its note: the frame's role)."""
        fb = batch.frames
        self.tracker.advance(float(fb.t[row]))  # the SDO's time-outs before it, in order
        self._emit(batch)
        note = self.usdo.feed(
            float(fb.t[row]), int(fb.can_id[row]), fb.payload(row), self._offset + row
        )
        batch.notes.setdefault(row, {}).update(note)
        self._emit_usdo(batch)

    def _emit_usdo(self, batch: DecodedBatch) -> None:
        n = len(batch)
        for ref, rec in self.usdo.pop_completed():
            row = -1 if ref is None else ref - self._offset
            if not 0 <= row < n:
                row = n - 1
            batch.add_record(row, rec)
            self._identify(row, rec)

    def process(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        n = len(fb)
        self._usdo_rows = None
        rows = self._rows(batch)
        if self._usdo_rows is not None:
            # USDO frames (CANopen FD) in this batch: every SDO-channel frame one at a time,
            # in order, so the two trackers' records come in the order they ended
            usdo_rows = set(self._usdo_rows.tolist())
            for row in sorted(usdo_rows.union(rows.tolist())):
                if row in usdo_rows:
                    self._feed_usdo(batch, row)
                else:
                    self._feed(batch, row)
        elif self.fast and len(rows) > 1 and not self._may_learn(batch, rows):
            self._cur_rows_arr = rows
            self._process_fast(batch, rows, self._rows_data)
            self._fill(batch)
            self._fill_strays(batch)
        else:
            for row in rows.tolist():
                self._feed(batch, row)
        if n:
            self.tracker.advance(float(fb.t[-1]))
            self._emit(batch)
            if self.usdo._pending:
                self.usdo.advance(float(fb.t[-1]))
                self._emit_usdo(batch)
        self._offset += n

    def _may_learn(self, batch: DecodedBatch, rows: np.ndarray) -> bool:
        """Whether a write to an SDO parameter object (0x1200-0x12FF), or a read that may
        name a node's device, may end in this batch.

        The first can add or move a channel mid-batch, which the plan's fixed channel
        map cannot follow; the second renames the node's objects from that transfer
        on, while the fast path names a batch's pairs at once. Then the whole batch
        goes through the tracker (a few batches of a log: where nodes start).
        """
        d = np.take(batch.frames.data, rows, axis=0)  # (~10x 2-D fancy indexing)
        self._rows_data = d  # (the fast path's plan reads them too)
        index = d[:, 1].astype(np.uint16) | (d[:, 2].astype(np.uint16) << 8)
        if ((index >= 0x1200) & (index <= 0x12FF)).any():
            return True
        if self.identifier is not None:
            ask = np.isin(index, IDENTITY_INDEX) & (d[:, 0] == sdo.INITIATE_UPLOAD_REQUEST)
            if ask.any():
                node = batch.frames.can_id[rows[ask]].astype(np.int64) - 0x600
                for nd, i, s in zip(
                    node.tolist(), index[ask].tolist(), d[ask, 3].tolist(), strict=True
                ):
                    if 1 <= nd <= 127 and self.identifier.may_identify(nd, i, s):
                        return True
        return any(
            x.index is not None and 0x1200 <= x.index <= 0x12FF
            for x in self.tracker._pending.values()
        )

    def _feed(self, batch: DecodedBatch, row: int) -> None:
        fb = batch.frames
        if self.usdo._pending:  # the USDO's time-outs before this frame, in order
            self.usdo.advance(float(fb.t[row]))
            self._emit_usdo(batch)
        role = self.tracker.feed(
            float(fb.t[row]), int(fb.can_id[row]), fb.payload(row), self._offset + row
        )
        # the tracker knows block segments, which carry no command specifier: its view wins
        note = {
            "role": role.text,
            "command": role.command,
            "index": role.index,
            "subindex": role.subindex,
        }
        if role.command == "block_segment":  # bit 7 `last` (c), bits 0-6 the sequence number
            data = fb.payload(row)
            note |= {
                "seqno": data[0] & 0x7F,
                "last": bool(data[0] & 0x80),
                "sdo_data": data[1:8].hex(),
            }
        if role.problem:
            note["sdo_problem"] = role.problem
        batch.notes.setdefault(row, {}).update(note)
        self._emit(batch)

    def _process_fast(
        self, batch: DecodedBatch, rows: np.ndarray, d: np.ndarray | None = None
    ) -> None:
        """Walk the SDO rows: quiet stretches in bulk, the rest one event at a time.

        Between two frames that must go through the tracker, nothing changes its
        state but the time; until a pending transfer would time out or see a new
        request, advancing is a no-op and every candidate pair is taken as is.
        """
        tracker = self.tracker
        p = fastpath.plan(batch, rows, tracker.timeout, tracker.extra_cob_ids(), d)
        strays = np.flatnonzero(p.stray).tolist()
        self._strays = strays
        self._stray_chunks: list[tuple[int, int]] = []  # (lo, hi) in strays: taken
        slow_at = np.flatnonzero(p.static_slow).tolist()
        m = len(rows)
        req_of = np.full(m, -1, np.int64)
        req_of[p.partner[p.cand]] = np.flatnonzero(p.cand)
        self._req_of_arr = req_of
        answers_arr = np.flatnonzero(p.is_partner)
        answers = answers_arr.tolist()
        self._answers = answers_arr
        # how each answer's transfer ends, for the tracker's `_ended` (a late abort joins it)
        self._ended_cob = p.req_cob[answers_arr]
        self._ended_aborted = p.aborted[answers_arr]
        self._chunks: list[tuple[int, int, int]] = []  # (first record slot, lo, hi) in answers
        rejected: list[int] = []  # answers whose request had to go through the tracker (sorted)
        rejected_set: set[int] = set()
        self._cp: tuple[list[int], list[float]] | None = None  # built by _candidates if asked
        self._cand_of: dict[int, list[int]] = {}
        self._plan = p
        self._plan_t = p.seen.t
        # per-position lists, built only when a frame is looked at alone: a quiet batch
        # is taken in one stretch and never reads them
        looked = False
        pos = 0
        si = 0
        while pos < m:
            while si < len(slow_at) and slow_at[si] < pos:
                si += 1
            stop = slow_at[si] if si < len(slow_at) else m
            ri = bisect.bisect_left(rejected, pos)
            if ri < len(rejected) and rejected[ri] < stop:
                stop = rejected[ri]
            if tracker._pending:
                stop = self._quiet_until(pos, stop)
            if stop > pos:
                # quiet stretch: every answer in it closes a pair whose request was taken
                lo, hi = bisect.bisect_left(answers, pos), bisect.bisect_left(answers, stop)
                if hi > lo:
                    self._take(batch, lo, hi)
                lo, hi = bisect.bisect_left(strays, pos), bisect.bisect_left(strays, stop)
                if hi > lo:
                    self._stray_chunks.append((lo, hi))
                pos = stop
                if pos >= m:
                    break
            i = pos
            pos += 1
            if not looked:
                looked = True
                row_of, partner, cand, is_partner, is_stray, req_cob, t = (
                    rows.tolist(),
                    p.partner.tolist(),
                    p.cand.tolist(),
                    p.is_partner.tolist(),
                    p.stray.tolist(),
                    p.req_cob.tolist(),
                    self._plan_t.tolist(),
                )
            if cand[i]:
                if tracker._pending:
                    tracker.advance(t[i])
                    self._emit(batch)
                if req_cob[i] not in tracker._pending:
                    continue  # taken: its answer closes it
                if tracker.cut_short(req_cob[i], t[i]):  # ends the transfer it interrupts
                    self._emit(batch)
                    continue  # taken too
                bisect.insort(rejected, partner[i])
                rejected_set.add(partner[i])
            elif is_partner[i] and i not in rejected_set:
                if tracker._pending:
                    tracker.advance(t[i])
                    self._emit(batch)
                lo = bisect.bisect_left(answers, i)
                self._take(batch, lo, lo + 1)
                continue
            elif is_stray[i]:
                if tracker._pending:
                    tracker.advance(t[i])
                    self._emit(batch)
                if req_cob[i] not in tracker._pending:  # idle channel: only a note
                    lo = bisect.bisect_left(strays, i)
                    self._stray_chunks.append((lo, lo + 1))
                    continue
            self._feed(batch, row_of[i])

    def _quiet_until(self, pos: int, stop: int) -> int:
        """First position from `pos` (before `stop`) where a pending transfer needs the tracker.

        That is where advance() would time one out (the first candidate frame late
        enough, found on the running maximum of their times: never later than the
        exact one) or where a candidate request or a stray response arrives on a
        pending channel. Before it, stepping frame by frame would only take the pairs
        (and strays) as they are.
        """
        (cp, cp_max), timeout = self._candidates(), self.tracker.timeout
        j0 = bisect.bisect_left(cp, pos)
        for cob, xfer in self.tracker._pending.items():
            # the first running maximum x with x - t_last > timeout: the tracker's own test
            # (not x > t_last + timeout, which rounds differently), searched by bisect in C
            t_last = xfer.t_last
            lo = bisect.bisect_right(cp_max, timeout, j0, key=lambda x, t0=t_last: x - t0)
            if lo < len(cp) and cp[lo] < stop:
                stop = cp[lo]
            same = self._cand_of.get(cob)
            if same is None:
                p = self._plan
                on = (p.cand | p.stray) & (p.req_cob == cob)
                same = self._cand_of[cob] = np.flatnonzero(on).tolist()
            k = bisect.bisect_left(same, pos)
            if k < len(same) and same[k] < stop:
                stop = same[k]
        return max(stop, pos)

    def _candidates(self) -> tuple[list[int], list[float]]:
        """Positions of the candidate requests, answers and strays (where advance() could end
        a pending transfer), and the running maximum of their times; built once per batch."""
        if self._cp is None:
            p = self._plan
            cp = np.flatnonzero(p.cand | p.is_partner | p.stray)
            cp_max = np.maximum.accumulate(self._plan_t[cp]).tolist() if cp.size else []
            self._cp = (cp.tolist(), cp_max)
        return self._cp

    def _take(self, batch: DecodedBatch, lo: int, hi: int) -> None:
        """Reserve the record slots of the fast pairs closed by answers[lo:hi] (filled by _fill)."""
        self._chunks.append((batch.records.reserve(hi - lo), lo, hi))
        cob, aborted = self._ended_cob[lo:hi], self._ended_aborted[lo:hi]
        if hi - lo > 16:  # only each channel's last answer tells: one update per channel
            # (COB-IDs fit 16 bits: np.unique's stable sort of uint16 is a radix sort)
            cob, last = np.unique(cob[::-1].astype(np.uint16), return_index=True)
            aborted = aborted[::-1][last]
        ended = zip(cob.tolist(), map(_ENDED.__getitem__, aborted.tolist()), strict=True)
        self.tracker._ended.update(ended)

    def _fill(self, batch: DecodedBatch) -> None:
        """Records of every pair taken in this batch, built column-wise; notes when read."""
        if not self._chunks:
            return
        rows = self._cur_rows_arr
        pick = np.concatenate([self._answers[lo:hi] for _, lo, hi in self._chunks])
        # the pairs' positions in the SDO rows (their columns as the plan read them), and rows
        pa, pb = self._req_of_arr[pick], pick
        a, b = rows[pa], rows[pb]
        fb = batch.frames
        seen = self._plan.seen
        slots = np.concatenate(
            [np.arange(slot, slot + hi - lo, dtype=np.int64) for slot, lo, hi in self._chunks]
        )
        cols = fastpath.pair_columns(seen, pa, pb, rows)
        latency = cols.latency
        info = lookup = self.tracker.object_info
        objects = None
        if info is not None:
            # answers as they are now: the records may be built after the model changed
            # (the distinct objects, sorted, and each pair's: what the records' build sorts)
            key = (cols.node << 24) | (cols.index << 8) | cols.subindex
            objects = np.unique(key, return_inverse=True)
            known = {k: info(k >> 24, (k >> 8) & 0xFFFF, k & 0xFF) for k in objects[0].tolist()}

            def lookup(node: int, index: int, sub: int, known=known):
                key = (node << 24) | (index << 8) | sub
                if key not in known:  # a mapping entry's object, named in its words
                    known[key] = info(node, index, sub)
                return known[key]

        memo: list[RecordColumns] = []

        def columns() -> RecordColumns:
            """All the records' fields, built once (the export reads them, the dicts too)."""
            if not memo:
                memo.append(fastpath.pair_record_columns(seen, pa, pb, lookup, latency, objects))
            return memo[0]

        def build(js: np.ndarray | None) -> list[dict]:
            if js is None:
                return columns().records()
            return fastpath.pair_records(seen, pa[js], pb[js], lookup, latency[js])

        batch.records.defer(FastPart(slots, cols, build, columns))

        def write_notes(notes: dict) -> None:
            req, resp = roles.pair_notes(fb, columns(), a, b)
            for ra, rb, na, nb in zip(a.tolist(), b.tolist(), req, resp, strict=True):
                LazyNotes.write(notes, ra, na)
                LazyNotes.write(notes, rb, nb)

        covers = np.concatenate((a, b))
        if isinstance(batch.notes, LazyNotes):
            batch.notes.defer(write_notes, covers)
        else:
            batch.notes = LazyNotes(batch.notes, write_notes, covers)

    def tick(self, batch: DecodedBatch, now: float) -> None:
        """Live, between frames: requests unanswered for longer than the timeout at `now`
        (the bus's clock) end as timeouts into `batch` (a zero-row one) while the bus is quiet."""
        self.tracker.advance(now)
        self._emit(batch)
        self.usdo.advance(now)
        self._emit_usdo(batch)

    def _fill_strays(self, batch: DecodedBatch) -> None:
        """Notes of the stray responses taken in this batch, written when read."""
        if not self._stray_chunks:
            return
        strays = self._strays
        pos = np.concatenate([np.arange(lo, hi) for lo, hi in self._stray_chunks])
        at = self._cur_rows_arr[np.asarray(strays, np.int64)[pos]]
        fb = batch.frames

        def write_notes(notes: dict) -> None:
            for row, note in zip(at.tolist(), fastpath.stray_notes(fb, at), strict=True):
                LazyNotes.write(notes, row, note)

        if isinstance(batch.notes, LazyNotes):
            batch.notes.defer(write_notes, at)
        else:
            batch.notes = LazyNotes(batch.notes, write_notes, at)

    def finish(self, batch: DecodedBatch) -> None:
        self.tracker.finish()
        self._emit(batch)
        self.usdo.finish()
        self._emit_usdo(batch)

    def _emit(self, batch: DecodedBatch) -> None:
        n = len(batch)
        for tx in self.tracker.pop_completed():
            ref = tx.ref if tx.ref is not None else -1
            row = ref - self._offset
            if not 0 <= row < n:
                row = n - 1  # completed by time passing (timeout) or at the end: after this batch
            rec = tx.to_record()
            batch.add_record(row, rec)
            self._identify(row, rec)

    def _identify(self, row: int, rec: dict) -> None:
        """An identity read (SDO or USDO) names the node's device from that transfer on."""
        if (
            self.identifier is not None
            and rec["direction"] == "upload"
            and rec["result"] == "ok"
            and (rec["index"], rec["subindex"]) in IDENTITY
        ):
            self.identifier.identify_now(row, rec)
