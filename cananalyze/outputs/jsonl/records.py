"""The records a batch's JSON lines hold besides its frames, each at its row: SDO transfers
and findings (`DecodedBatch.records_and_findings`), then the boot stories and LSS steps of
the decoder's commissioning processor (`DecodedBatch.commissioning`: an LSS step after the
frame that ended it, a boot story, judged at the end of the log, at the batch's end)."""

from __future__ import annotations

from cananalyze.core.records import DecodedBatch
from cananalyze.core.sdo_records import SdoRecords
from cananalyze.outputs.jsonl.encode import dumps
from cananalyze.outputs.jsonl.sdo import record_lines


def jsonl_records(batch: DecodedBatch) -> list[tuple[int, dict]]:
    return [*batch.records_and_findings(), *_commissioning(batch)]


def jsonl_record_lines(batch: DecodedBatch) -> list[tuple[int, bytes]]:
    """(row, JSON line) of each of `jsonl_records`, in its order; on a log of one bus
    the SDO transfers' lines come from their columns (`sdo.record_lines`), not dicts."""
    recs = batch.records
    if batch.several or not isinstance(recs, SdoRecords) or not recs:
        return [(row, _line(rec)) for row, rec in jsonl_records(batch)]
    lines = list(zip(recs.rows, record_lines(recs.fields()), strict=True))
    found = batch.findings.pairs() if len(batch.findings) else []
    return lines + [(row, _line(rec)) for row, rec in [*found, *_commissioning(batch)]]


def _line(rec: dict) -> bytes:
    return (dumps(rec) + "\n").encode()


def _commissioning(batch: DecodedBatch) -> list[tuple[int, dict]]:
    end = len(batch.frames)
    return [
        (
            end if c.row is None else c.row,
            c.record if c.bus is None else {**c.record, "bus": c.bus},
        )
        for c in batch.commissioning
    ]
