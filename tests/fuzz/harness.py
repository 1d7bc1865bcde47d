"""The one fuzz target shared by the property tests and the long campaign.

`run_log(data, suffix)` writes bytes to a temporary log and pushes them through
everything a user would: open_log, every batch, the full Decoder, the text and
JSONL writers and the summary. Only InputError may escape; every JSONL line must
parse. Anything else is a crash the harness re-raises for the fuzzer to report.
"""

from __future__ import annotations

import io
import json
import os
import tempfile

from cananalyze.core.errors import InputError
from cananalyze.formats.source import open_log
from cananalyze.outputs.jsonl.rows import JsonlWriter
from cananalyze.outputs.summary import Summary
from cananalyze.outputs.text.writer import TextWriter
from cananalyze.pipeline import Options, build_decoder

SUFFIXES = (".log", ".asc", ".blf", ".trc", ".csv", ".txt", ".log.gz", "")


def decode_all(batches, strict: bool = False) -> tuple[int, str, str]:
    """Decode batches to JSONL and text; returns (frames, jsonl, text). JSONL is validated."""
    decoder = build_decoder(Options())
    jout, tout = io.StringIO(), io.StringIO()
    jw, tw = JsonlWriter(jout), TextWriter(tout, color=False)
    summary = Summary()
    n = 0
    for fb in batches:
        db = decoder.decode(fb)
        n += len(fb)
        summary.add(db)
        jw.write(db)
        tw.write(db)
    tail = decoder.finish()
    summary.add(tail)
    jw.write(tail)
    tw.write(tail)
    summary.lines(250000, 0)
    summary.canopen_verdict()
    text = jout.getvalue()
    # JSON Lines are split on '\n' only (str.splitlines would also split inside
    # strings at U+0085/U+2028, which JSON need not escape)
    for line in text.split("\n")[:-1]:
        json.loads(line)  # raises on invalid JSON: a crash for the fuzzer
    return n, text, tout.getvalue()


def run_log(data: bytes, suffix: str = ".log", strict: bool = False, batch_size: int = 4096) -> int:
    """Frames read from `data` as a log file; InputError is an accepted outcome (returns -1)."""
    fd, path = tempfile.mkstemp(suffix=suffix or ".bin")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        try:
            src = open_log(path, strict=strict, batch_size=batch_size)
        except InputError as exc:
            _one_line(exc)
            return -1
        try:
            n, _, _ = decode_all(src.batches(), strict)
        except InputError as exc:
            _one_line(exc)
            return -1
        return n
    finally:
        os.unlink(path)


def _one_line(exc: InputError) -> None:
    msg = str(exc)
    assert msg and "\n" not in msg, f"InputError message is not one line: {msg!r}"
