"""LazyNotes: a batch's notes dict whose SDO roles are written only when read.

The fast path's frame notes ("SDO upload request 0x1018:01") matter only to the
text/JSONL outputs; `decode --summary`, `check` and exports never read them, and
building two dicts per transaction was a third of the SDO cost. The pending
notes are written in on the first access of any kind, and every dict method
goes through that, so to its readers this is the dict it would have been:
later processors that add to a row's notes see the SDO note first, as before.

Writers say which rows they cover: reading or writing one row that no pending
writer covers (the EMCY and NMT rows that event building and the EMCY decoder
ask for) is a plain dict access and leaves the SDO notes unwritten.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def _realising(name: str):
    method = getattr(dict, name)

    def wrapper(self, *args, **kwargs):
        self._realise()
        return method(self, *args, **kwargs)

    wrapper.__name__ = name
    return wrapper


def _realising_row(name: str):
    """A one-row method: realises only when a pending writer covers that row."""
    method = getattr(dict, name)

    def wrapper(self, row, *args, **kwargs):
        if self._pending and self._covered(row):
            self._realise()
        return method(self, row, *args, **kwargs)

    wrapper.__name__ = name
    return wrapper


class LazyNotes(dict):
    """dict of row -> note, with writers deferred until the first access."""

    def __init__(
        self, base: dict, fill: Callable[[dict], None], rows: np.ndarray | None = None
    ) -> None:
        """`rows`: the rows `fill` writes (None: unknown, any access realises)."""
        super().__init__(base)
        self._pending: list[Callable[[dict], None]] = []
        self._covers: list[np.ndarray] | None = []
        self._mask: np.ndarray | None = None
        self.defer(fill, rows)

    def defer(self, fill: Callable[[dict], None], rows: np.ndarray | None = None) -> None:
        self._pending.append(fill)
        if rows is None:
            self._covers = None
        elif self._covers is not None:
            self._covers.append(np.asarray(rows, np.int64))
        self._mask = None

    def _realise(self) -> None:
        while self._pending:
            fill = self._pending.pop(0)
            fill(self)  # writes with dict's own methods (see `write`)
        self._covers, self._mask = [], None

    def _covered(self, row) -> bool:
        """Whether a pending writer may write `row` (True when unsure)."""
        if not self._pending:
            return False
        if self._covers is None or type(row) is not int:
            return True
        mask = self._mask
        if mask is None:
            rows = np.concatenate(self._covers) if self._covers else np.zeros(0, np.int64)
            mask = np.zeros(int(rows.max()) + 1 if rows.size else 0, bool)
            mask[rows] = True
            self._mask = mask
        return 0 <= row < mask.size and bool(mask[row])

    def pending_rows(self) -> np.ndarray | None:
        """The rows pending writers will write (sorted, once each); None when there are no
        pending writers or one did not say. Until then no one has read or written them."""
        if not self._pending or self._covers is None:
            return None
        rows = np.concatenate(self._covers) if self._covers else np.zeros(0, np.int64)
        return np.unique(rows)

    @staticmethod
    def write(notes: dict, row: int, note: dict) -> None:
        """Merge `note` into row's note without re-entering the lazy methods."""
        current = dict.get(notes, row)
        if current is None:
            dict.__setitem__(notes, row, dict(note))
        else:
            current.update(note)

    for _name in (
        "__iter__", "__len__", "__repr__", "__eq__", "__ne__", "__or__", "__ior__",
        "__reversed__", "keys", "values", "items", "update", "popitem", "copy", "clear",
    ):  # fmt: skip
        locals()[_name] = _realising(_name)
    for _name in (
        "__getitem__", "__setitem__", "__delitem__", "__contains__", "get", "setdefault", "pop",
    ):  # fmt: skip
        locals()[_name] = _realising_row(_name)
    del _name

    def __reduce__(self):
        self._realise()
        return (dict, (dict(self.items()),))
