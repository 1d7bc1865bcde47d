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


@dataclass
class DecodedBatch:
    frames: FrameBatch
    service: np.ndarray  # uint8 Service
    node: np.ndarray  # int16, -1 = none
    pdo: np.ndarray  # uint8 PDO number, 0 = not a PDO
    notes: dict[int, dict] = field(default_factory=dict)  # row -> extra/overriding fields
    records: list[tuple[int, dict]] = field(default_factory=list)  # (row, record) done at row
    signals: list[SignalBlock] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.frames)

    def fields(self, i: int) -> dict:
        """All service fields of row i: stateless decode, then the stateful notes."""
        f = frame_fields(int(self.service[i]), self.frames.payload(i), bool(self.frames.flags[i] & FLAG_RTR))
        note = self.notes.get(i)
        if note:
            f.update(note)
        return f

    def add_record(self, row: int, record: dict) -> None:
        self.records.append((row, record))
