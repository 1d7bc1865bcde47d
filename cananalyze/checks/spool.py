"""Float columns appended per key (a node) over a whole log, held on disk past a small buffer.

The heartbeat rule learns a node's period from the median of all its gaps when
0x1017 is not known, so every heartbeat gap must last to the end of the log.
Held in memory, those gaps were what still grew with the log once the findings
were spooled: 24 bytes a heartbeat, +75 MB at 50M frames of the benchmark's bus
(16 nodes, 0x1017 unknown), and the heap fragmented around them. Here each key's
values go to a temporary file FLUSH rows at a time; `get` reads one key back,
when the rule judges that node at the end.
"""

from __future__ import annotations

import tempfile

import numpy as np

FLUSH = 4096  # rows of a key buffered before they are written (one record)


class KeyedSpool:
    """`columns` float64 columns per key; `get(key)` gives them whole, in the order added."""

    def __init__(self, columns: int) -> None:
        self.columns = columns
        self._file = None  # made at the first record: a short log never touches the disk
        self._records: dict[int, list[tuple[int, int]]] = {}  # key -> (offset, rows)
        self._buffer: dict[int, list[tuple[np.ndarray, ...]]] = {}  # key -> parts not written
        self._pending: dict[int, int] = {}  # key -> rows in its buffer
        self._disk = True  # False: no temporary file could be made (all kept in memory)

    def __contains__(self, key: int) -> bool:
        return key in self._records

    def keys(self) -> list[int]:
        return list(self._records)

    def __deepcopy__(self, memo) -> KeyedSpool:
        """A copy with the same values (rules are copied before any frame: then empty)."""
        copy = KeyedSpool(self.columns)
        for key in self._records:
            copy.add(key, *self.get(key))
        return copy

    def add(self, key: int, *values: np.ndarray) -> None:
        n = len(values[0])
        if not n:
            return
        self._buffer.setdefault(key, []).append(tuple(np.array(v, np.float64) for v in values))
        self._records.setdefault(key, [])
        self._pending[key] = self._pending.get(key, 0) + n
        if self._pending[key] >= FLUSH and self._disk:
            self._flush(key)

    def _flush(self, key: int) -> None:
        if self._file is None:
            try:  # unbuffered: a write that fails fails here, not at a later seek or read
                self._file = tempfile.TemporaryFile(prefix="cananalyze-gaps.", buffering=0)
            except OSError:  # no writable temporary directory: the old way, in memory
                self._disk = False
                return
        parts = self._buffer.pop(key)
        del self._pending[key]
        cols = [np.concatenate([p[c] for p in parts]) for c in range(self.columns)]
        try:
            at = self._file.seek(0, 2)
            for col in cols:
                _write_all(self._file, col.tobytes())
        except OSError:  # the temporary directory filled up: the rest stays in memory
            self._disk = False
            self._buffer[key] = [tuple(cols)]
            self._pending[key] = cols[0].size
            return
        self._records[key].append((at, cols[0].size))

    def get(self, key: int) -> tuple[np.ndarray, ...]:
        """Every value of `key`, per column (empty arrays for a key never added)."""
        parts: list[tuple[np.ndarray, ...]] = []
        for offset, rows in self._records.get(key, ()):
            self._file.seek(offset)
            raw = np.frombuffer(_read_all(self._file, 8 * rows * self.columns), np.float64)
            parts.append(tuple(raw[c * rows : (c + 1) * rows] for c in range(self.columns)))
        parts.extend(self._buffer.get(key, ()))
        if not parts:
            return tuple(np.zeros(0) for _ in range(self.columns))
        return tuple(np.concatenate([p[c] for p in parts]) for c in range(self.columns))


def _write_all(f, data: bytes) -> None:
    """An unbuffered file's write may take part of the bytes: write until all are."""
    view = memoryview(data)
    while view:
        view = view[f.write(view) :]


def _read_all(f, n: int) -> bytes:
    """n bytes (an unbuffered read may return fewer); short only at the end of the file."""
    parts, got = [], 0
    while got < n:
        part = f.read(n - got)
        if not part:
            break
        parts.append(part)
        got += len(part)
    return b"".join(parts)
