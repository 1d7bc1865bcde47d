"""`check --json`'s file, written a chunk of findings at a time.

A faulty bus has hundreds of thousands of findings; `json.dumps` of every record at
once held the records, the encoder's millions of small pieces and the whole text
together (about 2 GB for a faulty 10M-frame log). Here each chunk of rows becomes
records, is encoded by the same `json.dumps(..., indent=1)` and dropped, so the output
is byte for byte what one `json.dumps(records, indent=1) + "\\n"` gives, with only one
chunk's records alive.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence

import numpy as np

from cananalyze.core.finding import Finding
from cananalyze.core.finding_columns import FindingColumns

CHUNK = 4096  # findings encoded at a time: big enough that the per-chunk cost vanishes


def findings_json_parts(
    findings: Sequence[Finding] | FindingColumns, chunk: int = CHUNK
) -> Iterator[str]:
    """`check --json`'s text (every finding's record, in a list), in pieces of at most
    `chunk` records each."""
    n = len(findings)
    if n == 0:
        yield "[]\n"
        return
    yield "["
    for start in range(0, n, chunk):
        text = json.dumps(_records(findings, start, min(n, start + chunk)), indent=1)
        # "[\n <records>\n]": the items with the list's own separators, without its brackets
        yield ("" if start == 0 else ",") + text[1:-2]
    yield "\n]\n"


def _records(findings: Sequence[Finding] | FindingColumns, start: int, stop: int) -> list[dict]:
    if isinstance(findings, FindingColumns):
        # an index array, not a slice: the chunk's messages are built in a copy and
        # dropped with it, not cached on every row of the columns
        return findings.take(np.arange(start, stop)).records()
    return [f.record() for f in findings[start:stop]]
