"""The batch's SDO records as columns (`RecordColumns`, `SdoRecords.fields`) give the
same SDO table and events whether the fast path made them (columns) or they are held as
the dicts the tracker and `pair_outputs` make (a plain records list, as a filter leaves)."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import SAMPLES, generated_log, real_file
from exported import DEVICES, assert_parquet_is, assert_same_table_files, decoded_batches

from cananalyze.core.errors import ProblemLog
from cananalyze.core.sdo_records import RECORD_COLUMNS, RecordColumns, SdoRecords
from cananalyze.decode.events.build import EventState, batch_events
from cananalyze.outputs.capture import Collector
from cananalyze.outputs.tables.stream import SDO_COLUMNS
from cananalyze.outputs.tables.stream import TableSink as StreamTables


def _as_dicts(batch):
    """The same batch with its records as a plain list: readers fall back to the dicts."""
    batch.records = SdoRecords(list(batch.records))
    return batch


def _generated(tmp_path: Path) -> Path:
    return generated_log(tmp_path, 30000)


def _cases(tmp_path: Path, which: str):
    if which == "generated":
        return _generated(tmp_path), {"device": DEVICES}
    if which == "faults":
        return SAMPLES / "faults.log", {"network": str(SAMPLES / "network.toml")}
    if which == "commissioning":
        return SAMPLES / "commissioning.log", {"network": str(SAMPLES / "network.toml")}
    return real_file(which), {}


CASES = ["generated", "faults", "commissioning", "collin80__SavvyCAN/candump.log"]


@pytest.mark.parametrize("which", CASES)
@pytest.mark.parametrize("size", [997, None])
def test_events_same_from_columns_and_dicts(tmp_path, which, size):
    log, kw = _cases(tmp_path, which)
    s1, s2 = EventState(), EventState()
    off = 0
    fast = 0
    for b1, b2 in zip(
        decoded_batches(log, size, **kw), decoded_batches(log, size, **kw), strict=True
    ):
        fast += b1.records.fast_part() is not None
        e1 = batch_events(b1, off, s1)
        e2 = batch_events(_as_dicts(b2), off, s2)
        assert e1 == e2
        assert list(b1.records) == list(
            b2.records
        )  # reading the columns left the dicts as they were
        off += len(b1)
    if which in ("generated", "faults"):
        assert fast  # the column route was taken


@pytest.mark.parametrize("which", CASES)
def test_sdo_table_same_from_columns_and_dicts(tmp_path, which):
    """Both routes write the SDO table load()'s Capture builds from the same batches."""
    log, kw = _cases(tmp_path, which)
    for name, convert in (("cols", lambda b: b), ("dicts", _as_dicts)):
        with StreamTables(tmp_path / name) as st:
            for batch in decoded_batches(log, 997, **kw):
                st.write(convert(batch))
            st.close()
    assert_same_table_files(tmp_path / "cols", tmp_path / "dicts")
    collector = Collector(str(log))
    for batch in decoded_batches(log, 997, **kw):
        collector.add(batch)
    sdo = collector.capture(ProblemLog()).sdo
    assert_parquet_is(sdo, tmp_path / "cols" / "sdo.parquet")
    assert len(sdo) > 0 or which.endswith(".log")


def test_aborted_pairs_and_record_columns_agree():
    """Aborted fast pairs keep `pair_outputs`'s dict; the columns hold every record's fields."""
    assert SDO_COLUMNS == RECORD_COLUMNS
    aborted = 0
    for batch in decoded_batches(
        SAMPLES / "faults.log", None, network=str(SAMPLES / "network.toml")
    ):
        part = batch.records.fast_part()
        if part is None:
            continue
        fields = part.fields()
        aborted += len(fields.held)
        built = [batch.records[int(k)][1] for k in part.at]
        assert built == fields.records()
        for j, rec in enumerate(built):
            assert {c: rec[c] for c in RECORD_COLUMNS} == {
                c: fields.columns[c][j] for c in RECORD_COLUMNS
            }
        for j, rec in fields.held.items():
            assert rec["result"] == "abort" and fields.columns["result"][j] == "abort"
    assert aborted  # faults.log has server aborts answered on the fast path


@pytest.mark.parametrize("which", ["generated", "faults"])
def test_one_record_read_from_the_arrays_is_the_built_one(tmp_path, which):
    """`record` before the columns' lists exist (the OD tally reads a few records a
    batch) gives the fast part's own dict, key for key and type for type."""
    log, kw = _cases(tmp_path, which)
    read = 0
    for batch in decoded_batches(log, 997, **kw):
        part = batch.records.fast_part()
        if part is None:
            continue
        built = [batch.records[int(k)][1] for k in part.at]
        f = part.fields()
        fields = RecordColumns(f.arrays, f.held, f.name_labels)  # its lists not built yet
        one = [fields.record(j) for j in range(len(fields))]
        assert "columns" not in fields.__dict__
        assert one == built
        assert [[type(v) for v in r.values()] for r in one] == [
            [type(v) for v in r.values()] for r in built]  # fmt: skip
        assert [list(r) for r in one] == [list(r) for r in built]
        read += len(one)
    assert read
