"""The streaming table writer (`export --parquet/--csv` without MCAP/rrd) writes the same
tables as the Capture path: same Arrow schemas, same DataFrames read back with pandas,
whatever the batch size, with a bounded number of chunks waiting for the writer."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, SAMPLES, generated_log, real_file

from cananalyze.capture import Collector
from cananalyze.errors import ProblemLog
from cananalyze.io.source import read_all
from cananalyze.outputs.tables import writer as table_sink
from cananalyze.outputs.tables.pandas_like import MISSING, column
from cananalyze.outputs.tables.stream import TableSink as StreamTables
from cananalyze.outputs.tables.whole import TABLES, _plain_columns, write_csv, write_parquet
from cananalyze.pipeline import Options, build_decoder

DEVICES = {k: "dat7014" for k in range(1, 17)}


def _args(log: Path, **kw) -> Options:
    return Options(network=kw.get("network"), devices=kw.get("device") or {})


def given_profiles(opts: Options) -> dict[int, tuple[str, str]]:
    """What the nodes table says of the nodes the test declares (no network model here)."""
    return {n: (k, "user --device") for n, k in opts.devices.items()}


def _batches(log: Path, size: int | None, **kw):
    """Decoded batches of `size` frames (records' rows depend on the cuts: compare like with like)."""
    args = _args(log, **kw)
    decoder = build_decoder(args)
    fb = read_all(log)
    size = size or max(len(fb), 1)
    for start in range(0, len(fb), size):
        yield decoder.decode(fb.take(slice(start, start + size)))
    yield decoder.finish()


def _stream(log: Path, out: Path, fmt: str = "parquet", size: int | None = None, **kw) -> None:
    with StreamTables(out, fmt, profiles=given_profiles(_args(log, **kw))) as st:
        for batch in _batches(log, size, **kw):
            st.write(batch)
        st.close()


def _reference(log: Path, out: Path, fmt: str = "parquet", size: int | None = None, **kw):
    """The Capture path, as `export` runs it (no rules attached), on the same batches."""
    collector = Collector(str(log))
    for batch in _batches(log, size, **kw):
        collector.add(batch)
    cap = collector.capture(ProblemLog(), kw.get("network") or "", given_profiles(_args(log, **kw)))
    (write_parquet if fmt == "parquet" else write_csv)(cap, out)


def assert_same_tables(a: Path, b: Path, fmt: str = "parquet") -> None:
    for name in TABLES:
        if fmt == "csv":
            assert (a / f"{name}.csv").read_text() == (b / f"{name}.csv").read_text(), name
            continue
        fa, fb = pq.ParquetFile(a / f"{name}.parquet"), pq.ParquetFile(b / f"{name}.parquet")
        assert fa.schema_arrow.remove_metadata() == fb.schema_arrow.remove_metadata(), name
        ma = json.loads(fa.schema_arrow.metadata[b"pandas"])
        mb = json.loads(fb.schema_arrow.metadata[b"pandas"])
        assert ma == mb, name
        pd.testing.assert_frame_equal(
            pd.read_parquet(a / f"{name}.parquet"), pd.read_parquet(b / f"{name}.parquet")
        )


def _both(tmp_path: Path, log: Path, fmt: str = "parquet", size: int | None = None, **kw):
    _reference(log, tmp_path / "ref", fmt, size, **kw)
    _stream(log, tmp_path / "new", fmt, size, **kw)
    assert_same_tables(tmp_path / "ref", tmp_path / "new", fmt)


@pytest.mark.parametrize("name", ["demo.log", "faults.log", "commissioning.log", "faults.blf"])
def test_samples_same_tables(tmp_path, name):
    _both(tmp_path, SAMPLES / name, network=str(SAMPLES / "network.toml"))


@pytest.mark.parametrize("size", [1, 7, 1000])
def test_batch_size_invariance(tmp_path, size):
    log = SAMPLES / "faults.log"
    _both(tmp_path, log, size=size, network=str(SAMPLES / "network.toml"))


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_generated_devices_small_batches(tmp_path, fmt):
    """Generated 16-node traffic with device profiles (signals, SDO, EMCY), cut in batches
    that end mid-way through transfers and make categories appear after the first chunk."""
    _both(tmp_path, generated_log(tmp_path, 30000), fmt, size=997, device=DEVICES)


def test_csv_same_as_capture(tmp_path):
    _both(tmp_path, SAMPLES / "faults.log", "csv", size=5, network=str(SAMPLES / "network.toml"))


@pytest.mark.parametrize(
    "rel",
    [
        "collin80__SavvyCAN/candump.log",
        "RoboTrainerAID__za_experimental/candump.log",
        "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log",
    ],
)
def test_real_logs_same_tables(tmp_path, rel):
    _both(tmp_path, real_file(rel), size=4096)


def test_timestamps_going_back_resorted(tmp_path):
    """Batches that overlap in time: the stream re-sorts signals and events at the end."""
    fb = read_all(SAMPLES / "faults.log")
    fb.t[:] = fb.t[::-1].copy()  # time runs backwards: every batch starts before the last
    log = tmp_path / "back.log"
    lines = [
        f"({t:.6f}) can0 {cid:03X}#{bytes(d[:n]).hex().upper()}"
        for t, cid, d, n in zip(fb.t, fb.can_id, fb.data, fb.dlc, strict=True)
    ]
    log.write_text("\n".join(lines) + "\n")
    _both(tmp_path, log, size=13, network=str(SAMPLES / "network.toml"))


def _encodings(path: Path, column: str) -> set[str]:
    meta = pq.ParquetFile(path).metadata
    at = meta.schema.names.index(column)
    return {e for i in range(meta.num_row_groups) for e in meta.row_group(i).column(at).encodings}


@pytest.mark.parametrize("reverse", [False, True])
def test_time_columns_byte_stream_split(tmp_path, reverse):
    """Times are written BYTE_STREAM_SPLIT (half the encoding time, a third smaller), also
    when the end of the stream rewrites a table in time order; payloads never as dictionary."""
    log = SAMPLES / "faults.log"
    if reverse:
        fb = read_all(log)
        log = tmp_path / "back.log"
        log.write_text(
            "".join(
                f"({t:.6f}) can0 {cid:03X}#{bytes(d[:n]).hex().upper()}\n"
                for t, cid, d, n in zip(fb.t[::-1], fb.can_id, fb.data, fb.dlc, strict=True)
            )
        )
    _stream(log, tmp_path / "new", size=13, network=str(SAMPLES / "network.toml"))
    for name in ("frames", "signals"):
        path = tmp_path / "new" / f"{name}.parquet"
        assert "BYTE_STREAM_SPLIT" in _encodings(path, "t"), name
        assert pq.read_table(path).column("t").null_count == 0
    frames = tmp_path / "new" / "frames.parquet"
    assert not {"PLAIN_DICTIONARY", "RLE_DICTIONARY"} & _encodings(frames, "data")
    assert "RLE_DICTIONARY" in _encodings(frames, "can_id")
    assert "BYTE_STREAM_SPLIT" not in _encodings(tmp_path / "new" / "events.parquet", "t")


def test_writer_join_can_be_repeated_after_an_error():
    """close() joins, raises the writer's error, and abort() joins again (then __exit__
    once more): every join must return, with a one-deep queue too."""

    def boom():
        raise OSError(28, "No space left on device")

    done = threading.Event()
    errors = []

    def run():
        w = table_sink.WriterThread(1)
        w.put(boom)
        for _ in range(3):
            try:
                w.join()
            except OSError as exc:
                errors.append(exc)
        done.set()

    threading.Thread(target=run, daemon=True).start()
    assert done.wait(10), "WriterThread.join blocked"
    assert len(errors) == 3


def test_writer_queue_is_bounded(tmp_path, monkeypatch):
    """At most `depth` chunks wait for the writer thread, however slow it is."""
    seen = []
    original = table_sink.WriterThread.put

    def put(self, job):
        seen.append(self.queue.qsize())
        original(self, job)

    monkeypatch.setattr(table_sink.WriterThread, "put", put)
    _stream(SAMPLES / "faults.log", tmp_path / "x", size=3)
    assert seen and max(seen) <= 1  # StreamTables' default depth


def test_cut_off_export_leaves_no_table(tmp_path):
    class Boom(Exception):
        pass

    out = tmp_path / "cut"
    decoder = build_decoder(Options())
    fb = read_all(SAMPLES / "faults.log")
    with pytest.raises(Boom), StreamTables(out) as st:
        st.write(decoder.decode(fb.take(slice(0, 50))))
        raise Boom
    assert list(out.iterdir()) == []


def test_record_column_types_as_pandas():
    """pandas_like.column gives pandas' from_records inference for every mix of values."""
    values = [None, MISSING, 1, -3, 2.5, True, "a", [1], 2**64 - 1, float("nan")]
    for n in (1, 2, 3):
        for combo in itertools.product(values, repeat=n):
            for obj in (False, True):
                recs = [{} if v is MISSING else {"c": v} for v in combo]
                df = pd.DataFrame.from_records(recs, columns=["c"])
                if obj:
                    df["c"] = df["c"].astype(object)
                try:
                    table = pa.Table.from_pandas(_plain_columns(df), preserve_index=False)
                except (pa.ArrowException, ValueError, TypeError):
                    continue  # pandas cannot write it either
                meta = json.loads(table.schema.metadata[b"pandas"])["columns"][0]
                arr, pandas_type, numpy_type = column(list(combo), obj)
                assert (arr.type, pandas_type, numpy_type, arr.to_pylist()) == (
                    table.schema.field("c").type,
                    meta["pandas_type"],
                    meta["numpy_type"],
                    table.column("c").to_pylist(),
                ), (combo, obj)


def test_cli_streams_and_matches(tmp_path):
    log = SAMPLES / "faults.log"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "cananalyze",
            "export",
            str(log),
            "--no-check",
            "--parquet",
            str(tmp_path / "new"),
            "-q",
        ],
        check=True,
        cwd=ROOT,
    )
    _reference(log, tmp_path / "ref")
    assert_same_tables(tmp_path / "ref", tmp_path / "new")


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_small_row_groups_late_categories(tmp_path, monkeypatch, fmt):
    """Row groups of 50 rows: signal names and event kinds first seen after the file's
    categories were fixed make the sink re-code the file to pandas' sorted categories."""
    monkeypatch.setattr(table_sink, "ROW_GROUP", 50)
    _both(
        tmp_path, SAMPLES / "commissioning.log", fmt, size=11, network=str(SAMPLES / "network.toml")
    )
    if fmt == "parquet":
        assert pq.ParquetFile(tmp_path / "new" / "frames.parquet").num_row_groups > 1


def test_row_groups_cut_by_bytes(tmp_path, monkeypatch):
    """A row group is cut at ROW_GROUP_BYTES even when far from ROW_GROUP rows (so events
    and SDO rows do not wait in memory for dozens of batches): same tables. The frames
    table shows the table sink's cut (events here come all at once: the log is shorter
    than HOLD), the sdo table the record writer's."""
    from cananalyze.outputs.tables import stream as table_stream

    monkeypatch.setattr(table_sink, "ROW_GROUP_BYTES", 500)
    monkeypatch.setattr(table_stream, "ROW_GROUP_BYTES", 500)
    _both(tmp_path, SAMPLES / "faults.log", size=40, network=str(SAMPLES / "network.toml"))
    for name in ("frames", "sdo"):
        meta = pq.ParquetFile(tmp_path / "new" / f"{name}.parquet").metadata
        sizes = [meta.row_group(i).num_rows for i in range(meta.num_row_groups)]
        assert len(sizes) > 1, name
        assert max(sizes) <= 40, name  # a batch or less: cut by the bytes, not the rows


def _signal_batch(t: list[float]):
    from cananalyze.frames import FrameBatch
    from cananalyze.records import DecodedBatch, SignalBlock

    n = len(t)
    fb = FrameBatch.allocate(n, ("can0",))
    fb.t[:] = t
    batch = DecodedBatch(fb, np.zeros(n, np.uint8), np.zeros(n, np.int16), np.zeros(n, np.uint8))
    rows_a, rows_b = np.arange(0, n, 2), np.arange(1, n, 2)
    batch.signals = [
        SignalBlock(rows_a, 1, "tpdo1", 0x181, {"x": rows_a * 1.0, "y": rows_a * 2.0}, {}),
        SignalBlock(rows_b, 2, "tpdo1", 0x182, {"z": rows_b * 3.0}, {}),
    ]
    rows_of = [rows_a, rows_a, rows_b]
    col_of = [0, 1, 0]
    return batch, rows_of, col_of


def _blocks(batch) -> list[tuple[np.ndarray, int]]:
    return [(blk.rows, len(blk.columns)) for blk in batch.signals]


def test_signal_order_without_sort_equals_the_lexsort():
    """Strictly increasing times: frame by frame, columns in order, as the 4-key sort gives."""
    from cananalyze.outputs.tables.stream import _row_major_order

    batch, rows_of, col_of = _signal_batch([0.001 * k for k in range(9)])
    total = sum(len(r) for r in rows_of)
    order = _row_major_order(batch.frames.t, _blocks(batch), rows_of, col_of, total)
    row = np.concatenate(rows_of)
    col = np.repeat(col_of, [len(r) for r in rows_of])
    rank = np.repeat([0, 0, 1], [len(r) for r in rows_of])
    t = batch.frames.t[row]
    assert order is not None
    assert np.array_equal(order, np.lexsort((row, col, rank, t)))


def test_signal_order_with_equal_times_is_left_to_the_sort():
    """Two frames at the same time (millisecond logs): no shortcut, the caller sorts."""
    from cananalyze.outputs.tables.stream import _row_major_order

    batch, rows_of, col_of = _signal_batch([0.0, 0.0, 0.001, 0.002, 0.002, 0.003])
    total = sum(len(r) for r in rows_of)
    assert _row_major_order(batch.frames.t, _blocks(batch), rows_of, col_of, total) is None


def test_compute_kernels_registered_before_writer_threads():
    """pyarrow.compute is imported with the sink module, never first on a writer thread.

    Since Arrow 21 that import registers the compute kernels; done on one writer
    thread while another's Parquet writer looks a kernel up, the export failed at
    random with "No function registered with name: unique".
    """
    probe = "import sys; import cananalyze.outputs.tables.writer; print('pyarrow.compute' in sys.modules)"
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "True"
