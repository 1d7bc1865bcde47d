"""The record model: one DecodedBatch per batch, built once and read by every sink.

A DecodedBatch is a FrameBatch plus what the decoder learned about each row. Its
parts, each built in one place:

- frames: the FrameBatch and the classifier's columns (service, node, PDO number),
  with sparse per-row `notes` (an SDO frame's role in its transfer, a PDO problem);
- SDO transactions: `records` (core.sdo_records.SdoRecords), each completed at a row,
  made by the SDO tracker or its fast path;
- signals: `signals`, one SignalBlock of columns per PDO and mapping (PdoDecoder);
- findings: `findings` (checks.columns.FindingColumns, each at its row, so that
  streamed outputs place it among the frames: `records_and_findings`) (Checker);
- events: `events` and `states` (the event log and the NMT state changes, as
  columns), built by the pipeline once for every sink that shows them.

Outputs read only this; none decodes again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FrameBatch
from cananalyze.core.sdo_records import SdoRecords

if TYPE_CHECKING:
    from cananalyze.core.finding_columns import FindingColumns


def signal_path(node: int, pdo: str) -> str:
    """Where a series lives in MCAP and rerun: '/node/5/tpdo1', or '/dbc/Engine' for a DBC
    message on an identifier of no node (node -1)."""
    return f"/node/{node}/{pdo}" if node >= 0 else f"/dbc/{pdo}"


def on_bus(bus: str | None, path: str) -> str:
    """Where one bus's copy of a path lives when the log has several: '/can1' + path (MCAP
    topics, rerun entities); unchanged for one bus (None). Characters a path should not
    hold become '_'."""
    if bus is None:
        return path
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in bus) or "_"
    return f"/{safe}{path}"


@dataclass
class SignalBlock:
    """Decoded values of one PDO (one COB-ID and mapping) for some rows of a batch."""

    rows: np.ndarray  # row indices into the batch
    node: int
    pdo: str  # "tpdo2", "rpdo1"
    cob_id: int
    columns: dict[str, np.ndarray]  # signal name -> values, one per row
    units: dict[str, str | None]
    mapped_bytes: int = 0  # bytes the mapping needs; rows with a longer DLC carry extra bytes
    choices: dict[str, dict[int, str]] = field(default_factory=dict)  # a DBC's value tables
    objects: dict[str, tuple[int, int]] = field(default_factory=dict)  # name -> (index, sub)
    words: dict[str, int] = field(default_factory=dict)  # signals shown in words -> object index


def sender_counts(service: np.ndarray, node: np.ndarray) -> np.ndarray | None:
    """Frames per service and node as `counts[service, node + 1]` (column 0: the rows of
    no node), in one bincount; None when a node falls outside -1..127."""
    if node.size and not (int(node.min()) >= -1 and int(node.max()) <= 127):
        return None
    key = service.astype(np.intp) * 129
    key += node
    key += 1
    return np.bincount(key, minlength=256 * 129)[: 256 * 129].reshape(256, 129)


_SHAPE_FLAGS = FLAG_EXT | FLAG_RTR | FLAG_ERR | FLAG_FD  # a frame's bits besides its length


def sender_shapes(
    service: np.ndarray, node: np.ndarray, flags: np.ndarray, dlc: np.ndarray
) -> np.ndarray | None:
    """Frames per service, node and length as `counts[service, node + 1, dlc]`, in one
    bincount, when every row is a classic standard data frame (no flag that changes its
    bits on the wire) of length below 16 and of a node in -1..127 (nearly every batch of a
    CANopen bus); else None. Its first axis ends at the last service present (the
    services past it have no rows). `sender_counts` and the bits per node
    (protocol/busload) are sums of it: one pass over the rows for both."""
    if node.size and not (int(node.min()) >= -1 and int(node.max()) <= 127):
        return None
    if (flags & _SHAPE_FLAGS).any() or int(dlc.max(initial=0)) >= 16:
        return None
    # (service * 129 + node + 1) * 16 + dlc, the node's and length's part in node's dtype
    low = np.left_shift(node, 4, dtype=np.int16)  # -16..2032
    low += dlc
    key = np.multiply(service, 129 * 16, dtype=np.intp)
    key += low
    key += 16
    counts = np.bincount(key)
    per = 129 * 16
    services = -(-counts.size // per)
    if counts.size < services * per:
        counts = np.concatenate((counts, np.zeros(services * per - counts.size, counts.dtype)))
    return counts.reshape(services, 129, 16)


@dataclass
class DecodedBatch:
    frames: FrameBatch
    service: np.ndarray  # uint8 Service
    node: np.ndarray  # int16, -1 = none
    pdo: np.ndarray  # uint8 PDO number, 0 = not a PDO
    notes: dict[int, dict] = field(default_factory=dict)  # row -> extra/overriding fields
    records: SdoRecords = field(default_factory=SdoRecords)  # SDO transfers, by end row
    signals: list[SignalBlock] = field(default_factory=list)
    # Notes shared by many rows, kept columnar (e.g. one pdo_problem for every short PDO).
    row_notes: list[tuple[np.ndarray, dict]] = field(default_factory=list)
    findings: FindingColumns = field(default_factory=lambda: _no_findings())  # this batch's
    events: object = None  # events.columns.EventColumns, built once by the pipeline
    states: list = field(default_factory=list)  # NMT state changes (events.columns.Row)
    drive: list = field(default_factory=list)  # CiA 402 changes (network.drive_tracker)
    # boot stories and LSS steps completed in this batch (decode/commissioning.Commissioned)
    commissioning: list = field(default_factory=list)
    # each row's time after the SYNC before it, in ms, for synchronous PDOs (transmission
    # type 0-240 in force); NaN elsewhere; None: no such row (the checks' timing fills it)
    sync_latency: np.ndarray | None = None
    # several buses (else None): the bus of the whole batch (one bus's decoder), or of
    # each channel index (a frame row's bus is its channel's) and of each record (object
    # arrays: a batch merged from several)
    bus: str | None = None
    channel_bus: np.ndarray | None = None
    record_bus: np.ndarray | None = None
    _lazy: tuple | None = field(default=None, repr=False, compare=False)
    _senders: tuple | None = field(default=None, repr=False, compare=False)
    _shapes: tuple | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.records, SdoRecords):
            self.records = SdoRecords(self.records)

    def __len__(self) -> int:
        return len(self.frames)

    def __repr__(self) -> str:
        return (
            f"DecodedBatch({len(self)} frames, {len(self.records)} records, "
            f"{len(self.signals)} signal blocks, {len(self.findings)} findings)"
        )

    def select(self, mask: np.ndarray, keep_record) -> DecodedBatch:
        """The rows of `mask`, and the records (and findings) `keep_record(rec)` passes.

        What the user filtered (--node, --service, --from/--to) as a batch of its own,
        so that every sink shows the same selection. A kept record whose row is not
        kept goes after the batch's frames (row = len), where the text and JSONL
        outputs always put records of rows they do not show. Events are built after
        this, from what is kept.
        """
        mask = np.asarray(mask, bool)
        rows = np.flatnonzero(mask)
        n = rows.size
        pos = np.full(len(self) + 1, n, np.int64)  # a record of a row not kept: at the end
        pos[rows] = np.arange(n)
        frames = self.frames.take(rows)
        notes = {int(pos[r]): v for r, v in self.notes.items() if 0 <= r < len(self) and mask[r]}
        recs = self.records
        kept = [k for k, (_, rec) in enumerate(recs) if keep_record(rec)]
        records = recs.take(
            kept,
            [
                int(pos[row]) if 0 <= row < len(self) else n
                for row in map(recs.rows.__getitem__, kept)
            ],
        )
        signals = []
        for sb in self.signals:
            keep = mask[sb.rows]
            if keep.any():
                signals.append(
                    SignalBlock(
                        pos[sb.rows[keep]],
                        sb.node,
                        sb.pdo,
                        sb.cob_id,
                        {k: v[keep] for k, v in sb.columns.items()},
                        sb.units,
                        sb.mapped_bytes,
                        sb.choices,
                        sb.objects,
                        sb.words,
                    )
                )
        row_notes = []
        for r, note in self.row_notes:
            keep = mask[r]
            if keep.any():
                row_notes.append((pos[r[keep]], note))
        findings = self.findings
        if len(findings):
            keep = np.flatnonzero([keep_record(r) for r in findings.records()])
            findings = findings.take(keep)
            at = findings.row
            findings.row = np.where((at >= 0) & (at < len(self)), pos[np.clip(at, 0, len(self))], n)
        drive = [
            c._replace(row=int(pos[c.row]) if 0 <= c.row < len(self) else n)
            for c in self.drive
            if keep_record({"kind": "drive", "node": c.node, "t": c.t})
        ]
        commissioning = [
            c._replace(row=None if c.row is None else int(pos[min(max(c.row, 0), len(self))]))
            for c in self.commissioning
            if keep_record(c.record)
        ]
        return DecodedBatch(
            frames,
            self.service[rows],
            self.node[rows],
            self.pdo[rows],
            notes,
            records,
            signals,
            row_notes,
            findings,
            drive=drive,
            commissioning=commissioning,
            sync_latency=None if self.sync_latency is None else self.sync_latency[rows],
            bus=self.bus,
            channel_bus=self.channel_bus,
            record_bus=None
            if self.record_bus is None
            else self.record_bus[np.asarray(kept, np.int64)],
        )

    def row_index(self) -> tuple | None:
        """Row -> (signal block, position, shared note), built once when an output asks.

        Signals stay columnar in `signals`; only the output stage, which goes row by
        row anyway, turns them into per-row dicts.
        """
        if not self.signals and not self.row_notes:
            return None
        stamp = (len(self), len(self.signals), len(self.row_notes))
        if self._lazy is None or self._lazy[3] != stamp:
            n = len(self)
            block = np.full(n, -1, np.int32)
            pos = np.zeros(n, np.int64)
            shared = np.full(n, -1, np.int32)
            for k, sb in enumerate(self.signals):
                block[sb.rows] = k
                pos[sb.rows] = np.arange(sb.rows.size)
            for k, (rows, _) in enumerate(self.row_notes):
                shared[rows] = k
            self._lazy = (block, pos, shared, stamp)
        return self._lazy

    def add_record(self, row: int, record: dict) -> None:
        self.records.append(row, record)

    def records_and_findings(self) -> list[tuple[int, dict]]:
        """The records, then the findings' records: (row, record) in the order the
        streamed outputs (text, JSONL, dashboard) place them at their rows. On a log of
        several buses, each record that has none gains its `bus` (last; the findings'
        have theirs): a copy, the batch's records are not changed."""
        records = self.records
        if self.several and records:
            buses = self.record_buses(np.arange(len(records))).tolist()
            records = [
                (row, rec if bus is None or "bus" in rec else {**rec, "bus": bus})
                for (row, rec), bus in zip(records, buses, strict=True)
            ]
        if not len(self.findings):
            return records
        return [*records, *self.findings.pairs()]

    @property
    def several(self) -> bool:
        """The batch came from a log of several buses (seen so far): its rows and records
        say which (`bus`, `channel_bus`, `record_bus`)."""
        return self.bus is not None or self.channel_bus is not None or self.record_bus is not None

    def row_buses(self, rows: np.ndarray) -> np.ndarray:
        """The bus of each of these frame rows, an object array: None on a log of one bus
        so far, or for a row past the batch's frames."""
        if self.channel_bus is None:
            return _bus_at(None, self.bus, rows)
        out = np.empty(len(rows), object)
        inside = (rows >= 0) & (rows < len(self.frames))
        out[inside] = self.channel_bus[self.frames.channel[rows[inside]]]
        return out

    def block_bus(self, block: SignalBlock) -> str | None:
        """The bus of a signal block (one bus's decoder made it: its first row's), None on
        a log of one bus so far."""
        if not self.several or not len(block.rows):
            return None
        return self.row_buses(block.rows[:1])[0]

    def record_buses(self, slots: np.ndarray) -> np.ndarray:
        """The bus of each of these record slots, an object array: None on a log of one
        bus so far, or for a record added after the buses' batches were merged."""
        return _bus_at(self.record_bus, self.bus, slots)

    def sender_counts(self) -> np.ndarray | None:
        """`sender_counts` of the batch's rows, kept for its service and node arrays: the
        node tally and the boot-up rule both ask (after the processors, which may
        reclassify rows)."""
        got = self._senders
        if got is not None and got[0] is self.service and got[1] is self.node:
            return got[2]
        shapes = self.sender_shapes()
        if shapes is not None:
            counts = np.zeros((256, 129), np.int64)
            counts[: len(shapes)] = shapes.sum(axis=2)
        else:
            counts = sender_counts(self.service, self.node)
        self._senders = (self.service, self.node, counts)
        return counts

    def sender_shapes(self) -> np.ndarray | None:
        """`sender_shapes` of the batch's rows, kept for its service and node arrays like
        `sender_counts` (which sums it): the node tally's bits per node read it too."""
        got = self._shapes
        fb = self.frames
        if got is not None and got[0] is self.service and got[1] is self.node and got[3] is fb:
            return got[2]
        shapes = sender_shapes(self.service, self.node, fb.flags, fb.dlc)
        self._shapes = (self.service, self.node, shapes, fb)
        return shapes


def _no_findings() -> FindingColumns:
    from cananalyze.core.finding_columns import FindingColumns  # (checks imports this module)

    return FindingColumns()


def _bus_at(per: np.ndarray | None, bus: str | None, at: np.ndarray) -> np.ndarray:
    """per[at] as an object array, None where `at` is outside it; `bus` everywhere when
    the batch has one bus (`per` None)."""
    out = np.empty(len(at), object)
    if per is None:
        out[:] = bus
        return out
    inside = (at >= 0) & (at < len(per))
    out[inside] = per[at[inside]]
    return out
