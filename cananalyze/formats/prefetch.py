"""Read ahead in a thread: the next batch is parsed while this one is decoded.

The readers spend most of their time in numpy calls that release the GIL, and
the decoder mostly in Python, so on two cores the two overlap. One batch waits
at most: the decoder is the slower side, so a deeper queue is always full and
only adds a batch or two (6-7 MB each) to the peak, never speed (measured at
10M frames, issue 10), and memory stays flat in log length. Errors
raised by the reader reach the consumer unchanged, at the point they happened.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")
_END = object()


def prefetch(items: Iterable[T], depth: int = 1) -> Iterator[T]:
    """Yield `items` in order, producing up to `depth` ahead in a daemon thread."""
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def produce() -> None:
        try:
            for item in items:
                if stop.is_set():
                    return
                q.put((True, item))
            q.put((True, _END))
        except BaseException as exc:  # handed to the consumer, raised there
            q.put((False, exc))

    thread = threading.Thread(target=produce, name="cananalyze-reader", daemon=True)
    thread.start()
    try:
        while True:
            ok, item = q.get()
            if not ok:
                raise item
            if item is _END:
                return
            yield item
    finally:
        stop.set()
        while thread.is_alive():  # unblock a producer waiting on a full queue
            try:
                q.get_nowait()
            except queue.Empty:
                thread.join(0.01)
