"""SYNC (CiA 301 7.2.5): the optional counter byte and the frame's fields and text."""

from __future__ import annotations

FIRST_COUNTER = 1  # a counting producer starts at 1 and wraps to 1 after its overflow value
MAX_COUNTER = 240  # the largest synchronous counter overflow value (object 0x1019)


def next_counter(counter: int, overflow: int) -> int:
    """The counter after `counter` for a producer whose 0x1019 is `overflow`."""
    return counter % overflow + FIRST_COUNTER


def fields(data: bytes) -> dict:
    """JSONL fields of a SYNC frame: `counter` (null without one)."""
    return {"counter": data[0] if data else None}


def text(fields: dict) -> str:
    counter = fields.get("counter")
    return "SYNC" if counter is None else f"SYNC counter {counter}"
