"""The records a batch's JSON lines hold besides its frames, each at its row: SDO transfers
and findings (`DecodedBatch.records_and_findings`), then the boot stories and LSS steps of
the decoder's commissioning processor (`DecodedBatch.commissioning`: an LSS step after the
frame that ended it, a boot story, judged at the end of the log, at the batch's end)."""

from __future__ import annotations

from cananalyze.core.records import DecodedBatch


def jsonl_records(batch: DecodedBatch) -> list[tuple[int, dict]]:
    records = batch.records_and_findings()
    if not batch.commissioning:
        return records
    end = len(batch.frames)
    return [
        *records,
        *(
            (
                end if c.row is None else c.row,
                c.record if c.bus is None else {**c.record, "bus": c.bus},
            )
            for c in batch.commissioning
        ),
    ]
