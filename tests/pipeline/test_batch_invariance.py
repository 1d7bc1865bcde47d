"""Records must not depend on where batches are cut: live sniffing feeds batches of
one frame, offline reading feeds 64k. Same log, same frames, records and findings."""

from __future__ import annotations

import pytest
from conftest import SAMPLES

from cananalyze.formats.source import read_all
from cananalyze.outputs.jsonl.encode import dumps
from cananalyze.outputs.jsonl.rows import frame_record
from cananalyze.pipeline import Options, build_decoder


def _decode(name: str, size: int) -> list[str]:
    decoder = build_decoder(Options(network=SAMPLES / "network.toml", rules=SAMPLES / "rules.yaml"))
    fb = read_all(SAMPLES / name)
    out = []
    for start in range(0, len(fb), size):
        batch = decoder.decode(fb.take(slice(start, start + size)))
        by_row: dict[int, list[dict]] = {}
        for row, rec in batch.records_and_findings():  # findings: columns, placed at rows
            by_row.setdefault(row, []).append(rec)
        for i in range(len(batch)):
            out.append(dumps(frame_record(batch, i)))
            out.extend(dumps(r) for r in by_row.get(i, ()))
    out.extend(dumps(r) for _, r in decoder.finish().records_and_findings())
    return out


@pytest.mark.parametrize("name", ["faults.log", "commissioning.log"])
def test_same_records_whatever_the_batch_size(name):
    whole = _decode(name, 1 << 20)
    assert any('"kind":"finding"' in x for x in whole) or name == "commissioning.log"
    for size in (1, 7, 100):
        cut = _decode(name, size)
        assert len(cut) == len(whole), size
        diff = [(a, b) for a, b in zip(whole, cut, strict=True) if a != b]
        assert diff == [], f"batch size {size}: first difference {diff[:1]}"
