"""A text stream whose disk fails on every write (for writers that must raise it)."""

from __future__ import annotations

import io


class BrokenDisk(io.RawIOBase):
    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        raise OSError("disk full")


def broken_text_stream() -> io.TextIOWrapper:
    return io.TextIOWrapper(BrokenDisk(), encoding="utf-8")
