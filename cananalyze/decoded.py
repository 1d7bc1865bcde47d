"""DecodedBatch: a FrameBatch plus what the decoder learned about each row.

Columns for what every frame has (service, node, PDO number); sparse dicts and
lists for what only rare frames have (an SDO frame's role in its transfer, a
transaction record completed at that frame). Outputs read only this.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .frames import FLAG_RTR, FrameBatch
from .protocol.fields import frame_fields


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


@dataclass
class DecodedBatch:
    frames: FrameBatch
    service: np.ndarray  # uint8 Service
    node: np.ndarray  # int16, -1 = none
    pdo: np.ndarray  # uint8 PDO number, 0 = not a PDO
    notes: dict[int, dict] = field(default_factory=dict)  # row -> extra/overriding fields
    records: list[tuple[int, dict]] = field(default_factory=list)  # (row, record) done at row
    signals: list[SignalBlock] = field(default_factory=list)
    # Notes shared by many rows, kept columnar (e.g. one pdo_problem for every short PDO).
    row_notes: list[tuple[np.ndarray, dict]] = field(default_factory=list)
    _lazy: tuple | None = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.frames)

    def fields(self, i: int) -> dict:
        """All service fields of row i: stateless decode, then the stateful notes."""
        f = frame_fields(
            int(self.service[i]), self.frames.payload(i), bool(self.frames.flags[i] & FLAG_RTR)
        )
        lazy = self._lazy_index()
        if lazy is not None:
            block, pos, shared, _ = lazy
            b = int(block[i])
            if b >= 0:
                sb = self.signals[b]
                p = int(pos[i])
                f["signals"] = {k: v[p].item() for k, v in sb.columns.items()}
                f["units"] = {k: u for k, u in sb.units.items() if u}
            s = int(shared[i])
            if s >= 0:
                f.update(self.row_notes[s][1])
        note = self.notes.get(i)
        if note:
            f.update(note)
        return f

    def _lazy_index(self) -> tuple | None:
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
        self.records.append((row, record))
