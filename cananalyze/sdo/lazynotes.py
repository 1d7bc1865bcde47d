"""LazyNotes: a batch's notes dict whose SDO roles are written only when read.

The fast path's frame notes ("SDO upload request 0x1018:1") matter only to the
text/JSONL outputs; `decode --summary`, `check` and exports never read them, and
building two dicts per transaction was a third of the SDO cost. The pending
notes are written in on the first access of any kind, and every dict method
goes through that, so to its readers this is the dict it would have been:
later processors that add to a row's notes see the SDO note first, as before.
"""

from __future__ import annotations

from collections.abc import Callable


def _realising(name: str):
    method = getattr(dict, name)

    def wrapper(self, *args, **kwargs):
        self._realise()
        return method(self, *args, **kwargs)

    wrapper.__name__ = name
    return wrapper


class LazyNotes(dict):
    """dict of row -> note, with writers deferred until the first access."""

    def __init__(self, base: dict, fill: Callable[[dict], None]) -> None:
        super().__init__(base)
        self._pending: list[Callable[[dict], None]] = [fill]

    def defer(self, fill: Callable[[dict], None]) -> None:
        self._pending.append(fill)

    def _realise(self) -> None:
        while self._pending:
            fill = self._pending.pop(0)
            fill(self)  # writes with dict's own methods (see `write`)

    @staticmethod
    def write(notes: dict, row: int, note: dict) -> None:
        """Merge `note` into row's note without re-entering the lazy methods."""
        current = dict.get(notes, row)
        if current is None:
            dict.__setitem__(notes, row, dict(note))
        else:
            current.update(note)

    for _name in (
        "__getitem__", "__setitem__", "__delitem__", "__contains__", "__iter__", "__len__",
        "__repr__", "__eq__", "__ne__", "__or__", "__ior__", "__reversed__", "get", "keys",
        "values", "items", "setdefault", "update", "pop", "popitem", "copy", "clear",
    ):  # fmt: skip
        locals()[_name] = _realising(_name)
    del _name

    def __reduce__(self):
        self._realise()
        return (dict, (dict(self.items()),))
