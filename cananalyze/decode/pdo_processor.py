"""PdoDecoder: PDO rows become named values with units, one numpy column per signal.

Rows classified TPDO/RPDO are grouped by COB-ID and by the stretch of the batch in
which one configuration held (the network model's segments), and each group is
decoded at once by `decode_pdo`. The result stays columnar (`batch.signals`); the
per-row `signals`/`units` fields of the outputs are derived from it only when a row
is printed. Problems (short or long DLC, PDO not valid) are shared notes per group.
"""

from __future__ import annotations

import numpy as np

from cananalyze.config.node_config import entries_for
from cananalyze.core.columns.order import stable_order
from cananalyze.core.frames import FLAG_RTR
from cananalyze.core.records import DecodedBatch, SignalBlock
from cananalyze.decode.model import NetworkModel
from cananalyze.devices.words import WORDED
from cananalyze.protocol import mpdo
from cananalyze.protocol.datatypes import DATA_TYPES
from cananalyze.protocol.pdo import decode_pdo, long_payloads, words_of
from cananalyze.protocol.pdo_map import MapEntry
from cananalyze.protocol.services import Service

# an MPDO's first 4 bytes (address, index, sub-index) as a dummy UNSIGNED32 entry
_MPDO_HEAD = MapEntry(0x0007, 0, 32, "mpdo_head", 0x07)


class PdoDecoder:
    """Processor after the network model: decodes PDOs with the mapping in force."""

    def __init__(self, model: NetworkModel, skip: set[int] | frozenset[int] = frozenset()) -> None:
        self.model = model
        self.skip = np.array(sorted(c for c in skip if 0 <= c < 2048), np.intp)  # a DBC's ids
        self._words: tuple | None = None  # (FrameBatch, its data as uint64 words)

    def process(self, batch: DecodedBatch) -> None:
        if not self.model.bindings and len(self.model.segments) <= 1:
            return  # nothing mapped anywhere: skip the PDO scan entirely
        svc = batch.service
        fb = batch.frames
        segments = self.model.segments
        # only COB-IDs bound in some segment are decoded: dropped in the same mask, before
        # sorting (one pass over the batch's COB-IDs, not a gather of the PDO rows' first)
        bound = np.zeros(2049, bool)  # [2048]: every identifier past 11 bits (clipped there)
        cobs = [c for _, b in segments for c in b if 0 <= c < 2048]
        if cobs:
            bound[cobs] = True
        bound[self.skip] = False
        ids = np.flatnonzero(bound)
        if ids.size == 0:
            return
        if svc.dtype == np.uint8:  # TPDO 5, RPDO 6: one wrapping subtraction and a compare
            is_pdo = np.subtract(svc, np.uint8(Service.TPDO), dtype=np.uint8) <= 1
        else:
            is_pdo = (svc == Service.TPDO) | (svc == Service.RPDO)
        is_pdo &= (fb.flags & FLAG_RTR) == 0
        lo, hi = int(ids[0]), int(ids[-1])
        can_id = fb.can_id
        if can_id.dtype == np.uint32 and bound[lo : hi + 1].all():
            # the bound COB-IDs one range (a bus's TPDOs of consecutive nodes): a wrapping
            # subtraction and a compare, not a gather of the table by every identifier
            is_pdo &= np.subtract(can_id, np.uint32(lo), dtype=np.uint32) <= hi - lo
        else:
            is_pdo &= np.take(bound, can_id, mode="clip")
        rows = np.flatnonzero(is_pdo)
        if rows.size == 0:
            return
        cob = fb.can_id[rows]  # each below 2048 (bound)
        bounds = [start for start, _ in segments[1:]]
        # one sort groups rows by (segment, COB-ID), keeping row order inside each group;
        # as uint16 (the usual case: few segments) a counting sort (or numpy's radix sort)
        small = len(segments) <= 16
        key = cob.astype(np.uint16 if small else np.int64)
        if bounds:
            seg_of = np.searchsorted(np.asarray(bounds, np.int64), rows, side="right")
            key += (seg_of * 4096).astype(key.dtype)
        if small:
            order = stable_order(key, top=(len(segments) - 1) * 4096 + 2047)
        else:
            order = np.argsort(key, kind="stable")
        key_sorted = key[order]
        rows = rows[order]  # each group's rows a slice of these
        cuts = np.flatnonzero(key_sorted[1:] != key_sorted[:-1]) + 1
        starts = [0, *cuts.tolist()]
        ends = [*starts[1:], int(key_sorted.size)]
        for a, b in zip(starts, ends, strict=True):
            seg, cob_id = divmod(int(key_sorted[a]), 4096)
            binding = segments[seg][1].get(cob_id)
            if binding is None:
                continue
            group = rows[a:b]
            if binding.config.mpdo:
                self._decode_mpdo(batch, group, binding)
            elif binding.config.assumed and binding.config.mapping:
                self._decode_assumed(batch, group, binding)
            else:
                self._decode_group(batch, group, binding)
        self._words = None  # not kept past the batch

    def _decode_mpdo(self, batch: DecodedBatch, group: np.ndarray, binding) -> None:
        """MPDO frames (protocol/mpdo.py): one signal block per address and object, its
        value named and typed by the object's node (the destination of a DAM frame, the
        producer of a SAM one; the PDO's node for a DAM frame to all nodes)."""
        fb = batch.frames
        name = f"{binding.kind.upper()}{binding.number}"
        dlc = fb.dlc[group]
        short = dlc < mpdo.FRAME_BYTES
        if short.any():
            have = ",".join(map(str, sorted(set(dlc[short].tolist()))))
            what = f"DLC {have} shorter than the 8 bytes of an MPDO ({name}): not decoded"
            batch.row_notes.append((group[short], {"pdo_problem": what}))
            group = group[~short]
        if group.size == 0:
            return
        if self._words is None or self._words[0] is not fb:
            self._words = (fb, words_of(fb.data))
        cols = mpdo.split(fb.data[group])
        key = (cols.dam.astype(np.int64) << 40) | (cols.node.astype(np.int64) << 32)
        key |= (cols.index << 8) | cols.subindex
        for k in np.unique(key).tolist():
            at = group[key == k]
            dam, node = bool(k >> 40), (k >> 32) & 0x7F
            index, sub = (k >> 8) & 0xFFFF, k & 0xFF
            note = mpdo.fields(dam, node, index, sub)
            t0 = float(fb.t[at[0]])
            targets = [] if dam else self._dispatch(node, index, sub, t0)
            if not dam:
                scanner = self._entries(node, mpdo.SCANNER, t0)
                if scanner:  # the producer's list is known: does it let it send this?
                    note["scanned"] = any(mpdo.scanned(e, index, sub) for e in scanner)
            if targets:
                note["dispatched"] = [{"node": c, "index": i, "subindex": j} for c, i, j in targets]
            if len(targets) == 1:  # the value as the consumer's object it becomes
                owner, index, sub = targets[0]
            else:
                owner = node if node else binding.node
            entry = self._mpdo_entry(owner, index, sub)
            out = decode_pdo(None, fb.dlc[at], [_MPDO_HEAD, entry], words=self._words[1][at])
            batch.row_notes.append((at, {"mpdo": note}))
            batch.signals.append(
                SignalBlock(
                    rows=at,
                    node=binding.node,
                    pdo=f"{binding.kind}{binding.number}",
                    cob_id=int(fb.can_id[at[0]]),
                    columns=dict(out.values),
                    units={n: entry.unit for n in out.values},
                    mapped_bytes=mpdo.FRAME_BYTES,
                    objects={n: (index, sub) for n in out.values},
                )
            )

    def _entries(self, node: int, kind: str, t: float) -> list[int]:
        """The entries at t of a node's MPDO object lists of one kind (mpdo.LISTS: the scanner
        or the dispatching lists), within each list's count where known, from the log, the
        network file or the node's profile."""
        model = self.model
        lst = mpdo.LISTS[kind]
        out = []
        for index in range(lst.first, lst.last + 1):
            subs = model.subindices(node, index)
            if not subs:
                continue
            count = model.known(node, index, 0, t)
            for s in subs:
                if count is not None and s > count.value:
                    continue
                entry = model.known(node, index, s, t)
                if entry is not None and entry.value:
                    out.append(entry.value)
        return out

    def _dispatch(
        self, producer: int, index: int, sub: int, t: float
    ) -> list[tuple[int, int, int]]:
        """The consumers' objects a SAM frame's object is dispatched to at t: (node, index,
        sub-index) of every object dispatching list entry that names it."""
        out = []
        for node in sorted(self.model.nodes):
            for entry in self._entries(node, mpdo.DISPATCHER, t):
                hit = mpdo.dispatched(entry, producer, index, sub)
                if hit is not None:
                    out.append((node, *hit))
        return out

    def _mpdo_entry(self, node: int, index: int, sub: int) -> MapEntry:
        """How an MPDO's value shows: the object as the node's profile (else CiA 301's
        common objects) names and types it, at most the frame's 32 bits; else UNSIGNED32."""
        info = self.model.object_info(node, index, sub)
        dtype = DATA_TYPES.get(info[1]) if info is not None else None
        if dtype is not None and 0 < dtype.bits <= mpdo.VALUE_BITS:
            bits, code = dtype.bits, dtype.code
        else:
            bits, code = mpdo.VALUE_BITS, 0x07  # UNSIGNED32: the bytes as they are
        cfg = self.model.nodes.get(node)
        if cfg is not None and cfg.profile is not None:
            found = entries_for(cfg.profile, (index << 16) | (sub << 8) | bits, cfg.context)
            if len(found) == 1:
                return found[0]
        return MapEntry(index, sub, bits, f"obj_{index:04x}_{sub:02x}", code)

    def _decode_assumed(self, batch: DecodedBatch, group: np.ndarray, binding) -> None:
        """A profile's default mapping: each frame decoded by the entries its length holds
        (a CiA 401 module with fewer channels sends a shorter PDO), one group per length."""
        dlc = batch.frames.dlc[group]
        full = (sum(e.bits for e in binding.config.mapping) + 7) // 8
        for d in np.unique(dlc).tolist():
            if d > full:  # more bytes than the default maps: the node's mapping is another
                name = f"{binding.kind.upper()}{binding.number}"
                batch.row_notes.append(
                    (
                        group[dlc == d],
                        {
                            "pdo_problem": f"DLC {d} longer than the {full} bytes of {name}'s "
                            "default mapping, and no mapping is known from the log or a "
                            "file: not decoded (the node maps other objects)"
                        },
                    )
                )
                continue
            mapping, bits = [], 0
            for e in binding.config.mapping:
                if bits + e.bits > 8 * d:
                    break
                mapping.append(e)
                bits += e.bits
            if mapping:
                partial = len(mapping) < len(binding.config.mapping)
                self._decode_group(batch, group[dlc == d], binding, mapping, partial)

    def _decode_group(
        self,
        batch: DecodedBatch,
        group: np.ndarray,
        binding,
        mapping: list | None = None,
        partial: bool = False,
    ) -> None:
        fb = batch.frames
        mapping = binding.config.mapping if mapping is None else mapping
        if binding.problem:
            batch.row_notes.append((group, {"pdo_problem": binding.problem}))
        if not mapping:
            if not binding.problem:
                batch.row_notes.append(
                    (
                        group,
                        {
                            "pdo_problem": f"{binding.kind.upper()}{binding.number} "
                            f"of node {binding.node}: mapping not known (none mapped, or "
                            "not every entry seen yet)"
                        },
                    )
                )
            return
        if self._words is None or self._words[0] is not fb:
            self._words = (fb, words_of(fb.data))  # once per batch
        dlc = fb.dlc[group]
        if sum(e.bits for e in mapping) > 64:  # CANopen FD: up to 64 bytes (512 bits)
            cols = decode_pdo(None, dlc, mapping, long=long_payloads(fb, group))
        else:
            cols = decode_pdo(None, dlc, mapping, words=self._words[1][group])
        ok = ~cols.short
        for mask, what in (
            (
                cols.short,
                f"shorter than the {cols.bytes_needed} bytes mapped in "
                f"{binding.kind.upper()}{binding.number}: not decoded",
            ),
            (
                cols.extra & (not partial),  # a default mapping's entries the frame holds
                f"longer than the {cols.bytes_needed} bytes mapped: extra bytes ignored",
            ),
        ):
            if mask.any():  # one shared note per group of rows, not a dict per row
                have = ",".join(map(str, sorted(set(dlc[mask].tolist()))))
                batch.row_notes.append((group[mask], {"pdo_problem": f"DLC {have} {what}"}))
        if not ok.any() or not cols.values:
            return
        all_ok = bool(ok.all())
        units = {}
        for e in mapping:
            units.setdefault(e.name, e.unit)
        batch.signals.append(
            SignalBlock(
                rows=group if all_ok else group[ok],
                node=binding.node,
                pdo=f"{binding.kind}{binding.number}",
                cob_id=int(fb.can_id[group[0]]),
                columns={name: (v if all_ok else v[ok]) for name, v in cols.values.items()},
                units={name: units.get(name) for name in cols.values},
                mapped_bytes=cols.bytes_needed,
                objects={e.name: (e.index, e.subindex) for e in mapping if e.name in cols.values},
                words=self._words_of(binding.node, mapping, cols.values),
            )
        )

    def _words_of(self, node: int, mapping: list, values: dict) -> dict[str, int]:
        """Signals shown in words too (a CiA 402 node's statusword, controlword, modes)."""
        words = {
            e.name: e.index
            for e in mapping
            if e.index in WORDED and e.subindex == 0 and e.name in values
        }
        if not words or self.model.family(node) != 402:  # the family asked only if it tells
            return {}
        return words

    def finish(self, batch: DecodedBatch) -> None:
        pass
