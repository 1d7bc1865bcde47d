"""Signals held back while outputs are committed, so a kill cannot split an export.

Committing renames each finished temporary file over its target. A SIGTERM or
Ctrl-C between two renames would leave some outputs new and others missing, which
the all-or-nothing promise of `pipeline.run` forbids. Python runs signal handlers
only in the main thread, between bytecodes, so swapping in a handler that only
notes the signal is enough; the noted signal is raised again once the renames are
done, and the program ends as it would have (its outputs complete).
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

HELD = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def held() -> Iterator[None]:
    """Note SIGINT/SIGTERM inside the block; deliver them to the old handlers after it."""
    if threading.current_thread() is not threading.main_thread():
        yield  # handlers can only be changed in the main thread; nothing to hold there
        return
    seen: list[int] = []
    held = [s for s in HELD if signal.getsignal(s) is not None]  # None: set outside Python
    old = {s: signal.signal(s, lambda signum, frame: seen.append(signum)) for s in held}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        for s in dict.fromkeys(seen):
            signal.raise_signal(s)
