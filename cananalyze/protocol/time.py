"""TIME (CiA 301 7.2.6): TIME_OF_DAY, ms after midnight and days since the CANopen epoch."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

CANOPEN_EPOCH = datetime(1984, 1, 1, tzinfo=UTC)
SIZE = 6  # 28-bit ms (4 bytes, 4 bits reserved) + 16-bit days
MS_MASK = 0x0FFFFFFF
MALFORMED = "malformed"


def time_of_day(data: bytes) -> str | None:
    """ISO 8601 (UTC, ms) of a TIME_OF_DAY value, None when fewer than 6 bytes."""
    if len(data) < SIZE:
        return None
    ms = int.from_bytes(data[0:4], "little") & MS_MASK
    days = int.from_bytes(data[4:6], "little")
    when = CANOPEN_EPOCH + timedelta(days=days, milliseconds=ms)
    return when.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def fields(data: bytes) -> dict:
    """JSONL fields of a TIME frame: `time`; `problem` when it is too short."""
    when = time_of_day(data)
    return {"time": when} if when is not None else {"time": None, "problem": MALFORMED}


def text(fields: dict) -> str:
    when = fields.get("time")
    return f"TIME {when}" if when else f"TIME ({fields.get('problem', MALFORMED)})"
