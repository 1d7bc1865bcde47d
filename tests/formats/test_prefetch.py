"""prefetch: same items in the same order, reader errors raised where they happen."""

from __future__ import annotations

import threading

import pytest
from conftest import SAMPLES

from cananalyze.core.errors import InputError
from cananalyze.formats.prefetch import prefetch
from cananalyze.formats.source import open_log


def test_same_batches_in_order() -> None:
    plain = [b.t.copy() for b in open_log(SAMPLES / "demo.log").batches()]
    ahead = [b.t.copy() for b in prefetch(open_log(SAMPLES / "demo.log").batches())]
    assert len(plain) == len(ahead) and all(
        (a == b).all() for a, b in zip(plain, ahead, strict=True)
    )


def test_error_reaches_consumer_after_earlier_items() -> None:
    def items():
        yield 1
        yield 2
        raise InputError("log.txt line 3: bad frame")

    got = []
    with pytest.raises(InputError, match="line 3"):
        for x in prefetch(items()):
            got.append(x)
    assert got == [1, 2]


def test_close_stops_the_reader() -> None:
    produced = []

    def items():
        for i in range(10_000):
            produced.append(i)
            yield i

    it = prefetch(items(), depth=2)
    assert next(it) == 0
    it.close()
    assert not any(t.name == "cananalyze-reader" and t.is_alive() for t in threading.enumerate())
    assert len(produced) < 10
