"""The event log of a batch as numpy columns, and the `Row` tuple the Capture reads.

A polled bus makes hundreds of thousands of SDO and EMCY events; a tuple per
event, a Python sort with a key per event and a `zip(*rows)` to get columns
back cost more than building the texts. Columns sort with `np.lexsort`, split
with `searchsorted` and go to Arrow without a call per value. `rows()` gives
the Capture exactly the tuples it always had.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import starmap
from typing import NamedTuple

import numpy as np

NO_NODE = -1  # node column: no node (None in a Row)
NO_ROW = np.iinfo(np.int64).min  # row column: no frame row (None in a Row)
_LAST = 1 << 62  # where an event without a row sorts among its time's events

# kind labels; the kind column holds indexes into this list (it only grows)
KINDS: list[str] = ["sdo", "finding", "emcy", "nmt", "bootup", "nmt_state"]
_KIND_CODE = {k: i for i, k in enumerate(KINDS)}
SDO, FINDING, EMCY, NMT, BOOTUP, NMT_STATE = range(6)


def kind_code(kind: str) -> int:
    """Index of a kind label in `KINDS` (new labels are appended)."""
    code = _KIND_CODE.get(kind)
    if code is None:
        code = _KIND_CODE[kind] = len(KINDS)
        KINDS.append(kind)
    return code


class Row(NamedTuple):
    """An event as a plain tuple (what `batch_events` returns; `Event(*row)` is the same)."""

    t: float
    kind: str
    node: int | None
    level: int
    message: str
    row: int | None
    bus: str | None = None  # several buses: which one (None: one bus, or not known yet)


@dataclass
class EventColumns:
    """Events as columns: t, kind (index into KINDS), node, level, message (str objects), row,
    and on a log of several buses each event's bus (else None: no column at all)."""

    t: np.ndarray  # float64
    kind: np.ndarray  # uint8
    node: np.ndarray  # int16, NO_NODE for none
    level: np.ndarray  # int8
    message: np.ndarray  # object (str)
    row: np.ndarray  # int64, NO_ROW for none
    bus: np.ndarray | None = None  # object (str, None before the second bus was seen)

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls) -> EventColumns:
        return cls(
            np.zeros(0, np.float64),
            np.zeros(0, np.uint8),
            np.zeros(0, np.int16),
            np.zeros(0, np.int8),
            np.zeros(0, object),
            np.zeros(0, np.int64),
        )

    @classmethod
    def from_rows(cls, rows: list[Row] | list[tuple]) -> EventColumns:
        """Columns of event tuples (rare events: findings, SDO records off the fast path)."""
        if not rows:
            return cls.empty()
        t, kind, node, level, message, row = list(zip(*rows, strict=True))[:6]
        return cls(
            np.array(t, np.float64),
            np.array([kind_code(k) for k in kind], np.uint8),
            np.array([NO_NODE if n is None else n for n in node], np.int16),
            np.array(level, np.int8),
            texts(message),
            np.array([NO_ROW if r is None else r for r in row], np.int64),
        )

    @classmethod
    def concat(cls, parts: list[EventColumns]) -> EventColumns:
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        out = cls(
            *(
                np.concatenate([getattr(p, f) for p in parts])
                for f in ("t", "kind", "node", "level", "message", "row")
            )
        )
        if any(p.bus is not None for p in parts):
            out.bus = np.concatenate(
                [np.empty(len(p), object) if p.bus is None else p.bus for p in parts]
            )
        return out

    def take(self, index) -> EventColumns:
        """The events at `index` (an index array, a boolean mask or a slice)."""
        return EventColumns(
            self.t[index],
            self.kind[index],
            self.node[index],
            self.level[index],
            self.message[index],
            self.row[index],
            None if self.bus is None else self.bus[index],
        )

    def sort_key(self) -> np.ndarray:
        """The row as the events table sorts it: an event without a row after those with one."""
        return np.where(self.row == NO_ROW, _LAST, self.row)

    def rows(self) -> list[Row]:
        """The events as `Row` tuples, values as Python objects (what the Capture keeps)."""
        node = [None if n == NO_NODE else n for n in self.node.tolist()]
        row = self.row.tolist()
        if (self.row == NO_ROW).any():
            row = [None if r == NO_ROW else r for r in row]
        kind = list(map(KINDS.__getitem__, self.kind.tolist()))
        cols = [self.t.tolist(), kind, node, self.level.tolist(), self.message.tolist(), row]
        if self.bus is not None:
            cols.append(self.bus.tolist())
        return list(starmap(Row, zip(*cols, strict=True)))


def texts(values) -> np.ndarray:
    """A 1-D object array of the given strings (np.array would make a fixed-width str array)."""
    out = np.empty(len(values), object)
    out[:] = values
    return out
