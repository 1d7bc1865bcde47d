"""LazyRecords: a batch's records list whose fast-path SDO records are built when read.

`decode --summary` and `check` aggregate the fast path's transactions from columns
(`SdoColumns`) and never look at the dicts; building 30k dicts per million frames
was a fifth of the decode time. The fast path's slots hold placeholders until the
list is read: iteration, slicing, comparison or pickling write every record in; one
slot read by index writes only that record (the network model reads a few).
Appending (the tracker's records, findings) and `len` need nothing written.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Callable

import numpy as np


def _realising(name: str):
    method = getattr(list, name)

    def wrapper(self, *args, **kwargs):
        self._realise()
        return method(self, *args, **kwargs)

    wrapper.__name__ = name
    return wrapper


class LazyRecords(list):
    """list of (row, record); `defer` leaves some slots to a builder until they are read."""

    sdo_fast = None  # SdoColumns of the deferred records, while this list is the batch's
    sdo_fast_fields = None  # () -> fastpath.RecordColumns of the same records
    _build: Callable[[np.ndarray | None], list[dict]] | None = None  # while slots are deferred

    def defer(
        self,
        slots: np.ndarray,
        rows: list[int],
        build: Callable[[np.ndarray | None], list[dict]],
        columns=None,
        fields: Callable[[], object] | None = None,
    ) -> None:
        """Slots (ascending) to be filled with (rows[j], build(None)[j]); build(js) builds some.

        `columns` (SdoColumns) and `fields()` (the records' fields as lists) let
        readers take the deferred records without building them.
        """
        self._realise()
        self._slots = np.asarray(slots, np.int64)
        self._slot_list = self._slots.tolist()  # bisect on a list: ~20x np.searchsorted per read
        self._rows = rows
        self._build = build
        self._done: dict[int, dict] = {}  # j -> record already written by a single read
        self.sdo_fast = columns
        self.sdo_fast_fields = fields

    def _realise(self) -> None:
        build = self._build
        if build is None:
            return
        self._build = None
        records = build(None)
        done = self._done
        for j in done:
            records[j] = done[j]  # the same dict a reader already holds
        setitem = list.__setitem__
        for k, row, rec in zip(self._slots.tolist(), self._rows, records, strict=True):
            setitem(self, k, (row, rec))
        self._done = {}

    def __getitem__(self, key):
        if self._build is not None:
            if type(key) is not int or len(self._done) >= 16:
                self._realise()
            else:
                # readers of the other records (findings) ask slot by slot: keep it cheap
                k = key + len(self) if key < 0 else key
                slots = self._slot_list
                j = bisect_left(slots, k)
                if j < len(slots) and slots[j] == k:
                    rec = self._done.get(j)
                    if rec is None:
                        rec = self._done[j] = self._build(np.array([j]))[0]
                        list.__setitem__(self, k, (self._rows[j], rec))
        return list.__getitem__(self, key)

    def __reduce__(self):
        self._realise()
        return (list, (list(list.__iter__(self)),))

    for _name in (
        "__iter__", "__reversed__", "__contains__", "__eq__", "__ne__", "__lt__", "__le__",
        "__gt__", "__ge__", "__add__", "__mul__", "__rmul__", "__imul__", "__setitem__",
        "__delitem__", "__repr__", "index", "count", "copy", "sort", "reverse", "pop",
        "remove", "insert", "clear",
    ):  # fmt: skip
        locals()[_name] = _realising(_name)
    del _name
