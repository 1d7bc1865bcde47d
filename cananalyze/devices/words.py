"""Profile values in words: a column of statuswords, controlwords or modes as texts.

`word_column` formats each distinct value once and indexes the texts with the column
(a polled drive repeats a handful of statuswords a million times), so the outputs word
a bulk column with one `np.unique` and one table lookup, never a call per frame.
"""

from __future__ import annotations

import numpy as np

from cananalyze.devices import cia402
from cananalyze.protocol.pdo import fields_text

WORDED = frozenset(cia402.WORDS)  # the objects of a CiA 402 node that have words


def word(index: int, value: int) -> str | None:
    """One value in words (an SDO read or write), None for an object without words."""
    fields = word_fields(index, value)
    return None if fields is None else fields_text(fields)


def word_fields(index: int, value: int) -> dict | None:
    """One value as data ({"state": ..., "flags": [...]}), None for an object without words."""
    fn = cia402.FIELDS.get(index)
    if fn is None or not isinstance(value, int) or isinstance(value, bool):
        return None
    if index in (cia402.MODES, cia402.MODES_DISPLAY) and value > 127:
        value -= 256  # INTEGER8 read as unsigned
    return fn(value)


def fields_column(index: int, values: np.ndarray) -> tuple[list[dict | None], np.ndarray]:
    """(fields of the distinct values, position of each value's fields): `fields[inv]`."""
    uniq, inv = np.unique(np.asarray(values), return_inverse=True)
    return [word_fields(index, int(v)) for v in uniq.tolist()], inv.reshape(-1)


def word_column(index: int, values: np.ndarray) -> tuple[list[str], np.ndarray]:
    """(texts of the distinct values, position of each value's text): `texts[inv]`."""
    uniq, inv = np.unique(np.asarray(values), return_inverse=True)
    return [word(index, int(v)) or "" for v in uniq.tolist()], inv.reshape(-1)
