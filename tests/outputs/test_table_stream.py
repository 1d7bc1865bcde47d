"""`export --parquet/--csv` writes the tables of `load()`: read back with pandas (Parquet:
the schema, pandas metadata and DataFrames pandas' own file of load()'s tables gives; CSV:
every cell), whatever the batch size, with a bounded number of chunks waiting for the
writer; the findings are `check --json`'s."""

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
from exported import (
    DEVICES,
    NETWORK,
    assert_csv_tables,
    assert_parquet_tables,
    assert_same_table_files,
    backwards_log,
    decoded_batches,
    export,
    load_cut,
    plain_columns,
)

import cananalyze
from cananalyze.formats.source import read_all
from cananalyze.outputs.tables import writer as table_sink
from cananalyze.outputs.tables.pandas_like import MISSING, column
from cananalyze.outputs.tables.stream import FRAMES
from cananalyze.outputs.tables.stream import TableSink as StreamTables
from cananalyze.pipeline import Options, build_decoder


def _stream(log: Path, out: Path, fmt: str = "parquet", size: int | None = None, **kw) -> None:
    """The table sink fed directly (no run, no rules), batches of `size` frames."""
    with StreamTables(out, fmt) as st:
        for batch in decoded_batches(log, size, **kw):
            st.write(batch)
        st.close()


def _as_load(tmp_path: Path, log: Path, fmt: str = "parquet", size=None, **kw) -> Path:
    """Export the log; its tables must be load()'s of the same log and options."""
    out = export(log, tmp_path, (fmt,), size, **kw)[fmt]
    cap = load_cut(log, size, **kw)
    (assert_parquet_tables if fmt == "parquet" else assert_csv_tables)(cap, out)
    return out


@pytest.mark.parametrize("name", ["demo.log", "faults.log", "commissioning.log", "faults.blf"])
def test_samples_tables_are_load(tmp_path, name):
    out = _as_load(tmp_path, SAMPLES / name, network=NETWORK)
    if name.startswith("faults"):  # samples/README.md: 3 failed SDO transactions, 5 EMCY
        sdo = pd.read_parquet(out / "sdo.parquet")
        assert (sdo["result"] != "ok").sum() == 3
        events = pd.read_parquet(out / "events.parquet")
        assert (events["kind"] == "emcy").sum() == 5
        assert len(pd.read_parquet(out / "findings.parquet")) > 0


def test_frames_per_service_as_python_can_reads_them(tmp_path):
    """The frames table holds python-can's frames of the log, counted per COB-ID range."""
    import can

    log = SAMPLES / "commissioning.log"
    out = export(log, tmp_path, ("parquet",), network=NETWORK)["parquet"]
    frames = pd.read_parquet(out / "frames.parquet")
    msgs = list(can.LogReader(str(log)))
    assert len(frames) == len(msgs) == 1200  # samples/README.md
    assert frames["can_id"].tolist() == [m.arbitration_id for m in msgs]
    assert frames["t"].tolist() == pytest.approx([m.timestamp for m in msgs], abs=1e-6)
    assert frames["data"].tolist() == [bytes(m.data) for m in msgs]  # bytes, not hex text
    counts = frames["service"].astype(str).value_counts().to_dict()
    # samples/README.md: 114 SYNC, 345 heartbeats, 114 guard requests and replies,
    # 376 TPDOs, 20 RPDOs, 56 SDO requests and responses, 4 boot-ups, one NMT start
    assert counts["sync"] == 114 and counts["heartbeat"] == 345
    assert counts["guard_request"] == counts["guard_response"] == 114
    assert counts["tpdo"] == 376 and counts["rpdo"] == 20
    assert counts["sdo_request"] == counts["sdo_response"] == 56
    assert counts["bootup"] == 4 and counts["nmt"] == 1
    sdo = pd.read_parquet(out / "sdo.parquet")
    assert len(sdo) == 46 and (sdo["result"] == "ok").all()
    # device names read segmented from every node, and once more by block upload from node 6
    names = sdo[sdo["index"] == 0x1008].sort_values(["node", "protocol"])
    assert names[["node", "protocol", "value"]].values.tolist() == [
        [3, "segmented", "CO4201"],
        [5, "segmented", "DAT 7014"],
        [6, "block", "DAT 7130"],
        [6, "segmented", "DAT 7130"],
        [7, "segmented", "CPS_DCON"],
    ]


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
@pytest.mark.parametrize("size", [1, 7, 1000])
@pytest.mark.slow
def test_batch_size_invariance(tmp_path, fmt, size):
    """Cut anywhere (a frame at a time, like live), the files are those of one batch."""
    log = SAMPLES / "faults.log"
    whole = export(log, tmp_path / "whole", (fmt,), network=NETWORK)[fmt]
    cut = _as_load(tmp_path / "cut", log, fmt, size, network=NETWORK)
    assert_same_table_files(whole, cut, fmt)


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
@pytest.mark.slow
def test_generated_devices_small_batches(tmp_path, fmt):
    """Generated 16-node traffic with device profiles (signals, SDO, EMCY), cut in batches
    that end mid-way through transfers and make categories appear after the first chunk."""
    _as_load(tmp_path, generated_log(tmp_path, 30000), fmt, 997, device=DEVICES)


@pytest.mark.parametrize(
    "rel",
    [
        "collin80__SavvyCAN/candump.log",
        "RoboTrainerAID__za_experimental/candump.log",
        "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log",
    ],
)
def test_real_logs_tables_are_load(tmp_path, rel):
    _as_load(tmp_path, real_file(rel), size=4096)


def test_timestamps_going_back_resorted(tmp_path):
    """Batches that overlap in time: the stream re-sorts signals and events at the end."""
    log = backwards_log(SAMPLES / "faults.log", tmp_path / "back.log")
    _as_load(tmp_path, log, size=13, network=NETWORK)


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
        log = backwards_log(log, tmp_path / "back.log")
    _stream(log, tmp_path / "new", size=13, network=NETWORK)
    for name in ("frames", "signals"):
        path = tmp_path / "new" / f"{name}.parquet"
        assert "BYTE_STREAM_SPLIT" in _encodings(path, "t"), name
        assert pq.read_table(path).column("t").null_count == 0
    frames = tmp_path / "new" / "frames.parquet"
    assert not {"PLAIN_DICTIONARY", "RLE_DICTIONARY"} & _encodings(frames, "data")
    assert "RLE_DICTIONARY" in _encodings(frames, "can_id")
    assert "BYTE_STREAM_SPLIT" not in _encodings(tmp_path / "new" / "events.parquet", "t")


def test_frames_columns_never_null_are_required(tmp_path):
    """The frames table's columns that cannot be null are REQUIRED in the file (no
    definition levels to encode); node and pdo stay optional (pandas' Int16/Int8)."""
    _stream(SAMPLES / "faults.log", tmp_path / "new", size=13, network=NETWORK)
    path = tmp_path / "new" / "frames.parquet"
    parquet = pq.ParquetFile(path).schema
    levels = {parquet.column(i).name: parquet.column(i).max_definition_level for i in range(9)}
    assert levels == {**dict.fromkeys(FRAMES.required, 0), "node": 1, "pdo": 1}
    schema = pq.read_schema(path)
    assert [f.name for f in schema if not f.nullable] == list(FRAMES.required)
    assert pd.read_parquet(path)["node"].dtype == "Int16"


def test_frames_small_integers_delta_payloads_uncompressed(tmp_path):
    """dlc, flags, node and pdo are DELTA_BINARY_PACKED (no dictionary to hash every value
    into), payloads and the dictionary-coded columns are not snappy-compressed, times
    are; DuckDB, another Parquet reader, reads every value as python-can reads the log."""
    import can
    import duckdb

    log = SAMPLES / "faults.log"
    _stream(log, tmp_path / "new", size=13, network=NETWORK)
    path = tmp_path / "new" / "frames.parquet"
    for name in ("dlc", "flags", "node", "pdo"):
        assert "DELTA_BINARY_PACKED" in _encodings(path, name), name
        assert not {"PLAIN_DICTIONARY", "RLE_DICTIONARY"} & _encodings(path, name), name
    meta = pq.ParquetFile(path).metadata
    codecs = {
        meta.row_group(0).column(i).path_in_schema: meta.row_group(0).column(i).compression
        for i in range(meta.num_columns)
    }
    assert codecs["t"] == "SNAPPY"
    assert {codecs[c] for c in FRAMES.uncompressed} == {"UNCOMPRESSED"}
    with can.LogReader(str(log)) as reader:
        msgs = [m for m in reader if not m.is_error_frame]
    got = duckdb.sql(f"SELECT dlc, can_id FROM '{path}' ORDER BY t, can_id").fetchall()
    assert sorted(got) == sorted((m.dlc, m.arbitration_id) for m in msgs)
    nodes = duckdb.sql(f"SELECT count(node), count(pdo), sum(node) FROM '{path}'").fetchall()[0]
    table = pq.read_table(path)
    assert nodes == (
        len(table) - table.column("node").null_count,
        len(table) - table.column("pdo").null_count,
        int(table.column("node").drop_null().to_numpy().astype(np.int64).sum()),
    )


def test_frames_every_column_compressed_with_the_codec_asked_for(tmp_path):
    """Only the default codec (snappy, for speed) leaves payloads uncompressed: a user
    who asks for zstd wants the smaller file."""
    dest = tmp_path / "z"
    _cli(
        "export",
        str(SAMPLES / "faults.log"),
        "--parquet",
        str(dest),
        "--parquet-compression",
        "zstd",
        "-q",
    )
    meta = pq.ParquetFile(dest / "frames.parquet").metadata
    got = {meta.row_group(0).column(i).compression for i in range(meta.num_columns)}
    assert got == {"ZSTD"}


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
    assert not out.exists()  # the folder it made is removed too (issue 24)
    out.mkdir()  # a folder the user had stays, empty
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
                    table = pa.Table.from_pandas(plain_columns(df), preserve_index=False)
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


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, cwd=ROOT
    )


def test_cli_export_tables_are_load_and_findings_are_check_json(tmp_path):
    """`export` runs the CANopen rules and the rules file's assertions by default: its
    findings table holds what `check --json` reports of the same log, and every table is
    load()'s with the same network and rules."""
    log, rules = SAMPLES / "faults.log", SAMPLES / "rules.yaml"
    given = ["--network", NETWORK, "--rules", str(rules)]
    r = _cli("export", str(log), *given, "--parquet", str(tmp_path / "pq"), "-q")
    assert r.returncode == 0, r.stderr
    r = _cli("check", str(log), *given, "--json", str(tmp_path / "f.json"), "-q")
    assert r.returncode == 1, r.stderr  # samples/README.md: rules.yaml fails on faults
    reported = json.loads((tmp_path / "f.json").read_text())
    findings = pd.read_parquet(tmp_path / "pq" / "findings.parquet")
    assert len(findings) == len(reported) > 5
    assert {"emcy", "heartbeat"} <= set(findings["rule"])
    want = plain_columns(pd.DataFrame.from_records(reported)).drop(columns="kind")
    for col in findings.columns:
        got = [None if pd.isna(v) else v for v in findings[col]]
        assert got == [None if pd.isna(v) else v for v in want[col]], col
    assert_parquet_tables(cananalyze.load(log, network=NETWORK, rules=rules), tmp_path / "pq")


def test_findings_written_in_chunks_are_load_and_typed_over_the_whole_column(tmp_path, monkeypatch):
    """The findings table is converted a few rows at a time (its values are Python
    objects); the column types are still decided over the whole column, as pandas'
    from_records: faults.log with the rules file mixes text, numbers and ranges in
    `measured` and `expected`, so chunks of 2 rows each see only some of the mix, and
    the chunks written with the first ones' types are written again."""
    from cananalyze.outputs.tables import stream as table_stream

    log, rules = SAMPLES / "faults.log", SAMPLES / "rules.yaml"
    whole = export(log, tmp_path / "whole", network=NETWORK, rules=rules)["parquet"]
    monkeypatch.setattr(table_stream, "FINDINGS_CHUNK", 2)
    monkeypatch.setattr(table_stream, "ROW_GROUP_BYTES", 500)
    dropped = []  # the file written with the first chunks' types, dropped when they changed
    discard = table_stream._RecordWriter.discard
    monkeypatch.setattr(
        table_stream._RecordWriter,
        "discard",
        lambda w: dropped.append(w.schema.names) or discard(w),
    )
    cut = export(log, tmp_path / "cut", network=NETWORK, rules=rules)["parquet"]
    # emcy texts first, numbers later: `measured` became text
    assert list(table_stream.FINDING_COLUMNS) in dropped
    assert pq.ParquetFile(cut / "findings.parquet").num_row_groups > 1
    got = pq.read_table(cut / "findings.parquet")
    assert got.equals(pq.read_table(whole / "findings.parquet"), check_metadata=True)
    measured = got.column("measured")
    assert measured.type == pa.large_string()  # text, ints, floats: the mix as text
    assert {"0x8100", "3", "3276.7"} <= set(measured.to_pylist())
    assert_parquet_tables(cananalyze.load(log, network=NETWORK, rules=rules), cut)


def test_findings_filling_a_row_group_end_without_an_empty_one(tmp_path):
    """A findings table that filled its last row group as it came was closed with an
    empty one more, built by `Schema.empty_table`, which imports pandas (0.4-0.9 s of
    a 10M-frame export whose 47k findings filled one row group)."""
    log = SAMPLES / "faults.log"
    out = tmp_path / "pq"
    code = (
        "import sys; from cananalyze.outputs.tables import stream; "
        "stream.ROW_GROUP_BYTES = 1; stream.FINDINGS_CHUNK = 5; "
        "from cananalyze.cli.main import main; "
        f"rc = main(['export', {str(log)!r}, '--parquet', {str(out)!r}, '-q']); "
        "print(rc, 'pandas' in sys.modules)"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True
    )
    assert r.stdout.split() == ["0", "False"], r.stderr
    meta = pq.ParquetFile(out / "findings.parquet").metadata
    sizes = [meta.row_group(i).num_rows for i in range(meta.num_row_groups)]
    assert len(sizes) > 1 and min(sizes) > 0, sizes
    assert sum(sizes) == len(pd.read_parquet(out / "findings.parquet")) > 5


def test_cli_no_check_leaves_the_findings_table_empty(tmp_path):
    log = SAMPLES / "faults.log"
    r = _cli("export", str(log), "--no-check", "--parquet", str(tmp_path), "-q")
    assert r.returncode == 0, r.stderr
    assert len(pd.read_parquet(tmp_path / "findings.parquet")) == 0
    assert len(pd.read_parquet(tmp_path / "frames.parquet")) == 933


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_small_row_groups_late_categories(tmp_path, monkeypatch, fmt):
    """Row groups of 50 rows: signal names and event kinds first seen after the file's
    categories were fixed make the sink re-code the file to pandas' sorted categories."""
    monkeypatch.setattr(table_sink, "ROW_GROUP", 50)
    out = _as_load(tmp_path, SAMPLES / "commissioning.log", fmt, size=11, network=NETWORK)
    if fmt == "parquet":
        assert pq.ParquetFile(out / "frames.parquet").num_row_groups > 1


def test_row_groups_cut_by_bytes(tmp_path, monkeypatch):
    """A row group is cut at ROW_GROUP_BYTES even when far from ROW_GROUP rows (so events
    and SDO rows do not wait in memory for dozens of batches): same tables. The frames
    table shows the table sink's cut (events here come all at once: the log is shorter
    than HOLD), the sdo table the record writer's."""
    from cananalyze.outputs.tables import stream as table_stream

    monkeypatch.setattr(table_sink, "ROW_GROUP_BYTES", 500)
    monkeypatch.setattr(table_stream, "ROW_GROUP_BYTES", 500)
    out = _as_load(tmp_path, SAMPLES / "faults.log", size=40, network=NETWORK)
    for name in ("frames", "sdo"):
        meta = pq.ParquetFile(out / f"{name}.parquet").metadata
        sizes = [meta.row_group(i).num_rows for i in range(meta.num_row_groups)]
        assert len(sizes) > 1, name
        assert max(sizes) <= 40, name  # a batch or less: cut by the bytes, not the rows


def _signal_batch(t: list[float]):
    from cananalyze.core.frames import FrameBatch
    from cananalyze.core.records import DecodedBatch, SignalBlock

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
    """pyarrow._compute is imported with the sink module, never first on a writer thread.

    Since Arrow 21 that import registers the compute kernels; done on one writer
    thread while another's Parquet writer looks a kernel up, the export failed at
    random with "No function registered with name: unique". pyarrow.compute (which
    imports it too) is not needed: its per-kernel wrappers cost ~60 ms of CPU.
    """
    probe = (
        "import sys; import cananalyze.outputs.tables.writer, cananalyze.outputs.tables.stream; "
        "print('pyarrow._compute' in sys.modules, 'pyarrow.compute' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "True False"


def test_export_with_findings_never_imports_pandas(tmp_path):
    """Late findings make the events table re-sorted at the end; that rewrite took pyarrow's
    to_numpy/take, which import pandas (0.5-0.8 s a run) behind the writer's back."""
    log = generated_log(tmp_path, 60_000)
    code = (
        "import sys; from cananalyze.cli.main import main; "
        f"rc = main(['export', {str(log)!r}, '--parquet', {str(tmp_path / 'pq')!r}, '-q']); "
        "print(rc, 'pandas' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True
    )
    assert out.stdout.split() == ["0", "False"], out.stderr
    events = pq.read_table(tmp_path / "pq" / "events.parquet")
    kinds = events.column("kind").to_pylist()
    assert "finding" in kinds  # the case that is re-sorted
    t = events.column("t").to_pylist()
    assert t == sorted(t)


def test_event_messages_column_as_strings_with_nulls() -> None:
    """The events' message column (texts taken as str, not looked at for None) is the
    column `strings` with nulls builds, a None among them (a null) and non-ASCII too."""
    from cananalyze.core.columns import arrow_build as ab
    from cananalyze.outputs.tables.stream import _message_column

    for values in (["a", "bé", ""], ["a", None, "c"], [], ["x" * 300, "\x1f"]):
        got = _message_column(np.array(values + [0], object)[:-1])
        want = ab.strings(values, large=True)
        assert got.equals(want) and got.to_pylist() == values
