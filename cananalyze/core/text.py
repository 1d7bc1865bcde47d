"""Names from input files made safe to print: control characters shown, never obeyed.

A channel's name in a log, an object's name in an EDS, a signal's in a DBC, a node's in
a network file or a rule's in a rules file reach terminals (decode's lines, check's
findings, the summary, `devices`). An escape sequence in one could recolour, move the
cursor, retitle or clear the user's terminal, and a newline could forge an output line.
Each such name passes `printable` where it is read, once.
"""

from __future__ import annotations

import re

# C0 controls (newline and tab too: a name is one line), DEL and the C1 controls
# (U+009B is a one-character CSI on some terminals)
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f]")


def printable(text: str) -> str:
    """`text` with each control character written as a visible escape (ESC as \\x1b)."""
    if not _CONTROL.search(text):
        return text
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", text)


def printable_or_none(text: str | None) -> str | None:
    return None if text is None else printable(text)
