"""Whether to colour terminal output, and the colours, in one place.

Colour only on a terminal, never when the user says no: `--no-color` or the
NO_COLOR environment variable (https://no-color.org: any non-empty value).
"""

from __future__ import annotations

import os
from typing import TextIO

RESET = "\033[0m"
SERVICE = {
    "nmt": "\033[1;35m",
    "sync": "\033[2m",
    "time": "\033[2m",
    "emcy": "\033[1;31m",
    "tpdo": "\033[36m",
    "rpdo": "\033[34m",
    "sdo_request": "\033[33m",
    "sdo_response": "\033[33m",
    "heartbeat": "\033[32m",
    "bootup": "\033[1;32m",
    "guard_request": "\033[32m",
    "guard_response": "\033[32m",
    "lss_master": "\033[35m",
    "lss_slave": "\033[35m",
    "error_frame": "\033[1;31m",
    "errctl_invalid": "\033[33m",  # malformed: noticed, not alarming
    "srdo": "\033[1;36m",
    "srdo_inverted": "\033[2;36m",
    "gfc": "\033[1;31m",
    "other": "\033[2m",
}
SEVERITY = {"error": "\033[1;31m", "warning": "\033[33m", "info": "\033[2m"}


def use_colour(stream: TextIO, no_color: bool = False) -> bool:
    """Colour for this stream: a terminal, and neither --no-color nor NO_COLOR."""
    if no_color or os.environ.get("NO_COLOR"):
        return False
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def paint(text: str, colour: str, on: bool) -> str:
    return f"{colour}{text}{RESET}" if on and colour else text
