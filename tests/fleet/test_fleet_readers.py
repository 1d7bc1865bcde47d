"""Datasets that query engines like (issue 39 item 4): the `date` partition typed as a
date for every reader, and `fleet compact` rewriting small parts into large time-ordered
files without losing, duplicating or orphaning a log's rows. Checked with pyarrow and
DuckDB directly, not through cananalyze's readers."""

from __future__ import annotations

import json
import os
import shutil
from collections import Counter
from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from conftest import REAL

from cananalyze.cli.main import main
from cananalyze.fleet import compact, orchestrate, query, schema, task
from cananalyze.fleet.orchestrate import run_fleet

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
# real logs read where they are (when the shared data is there): other loggers' files
REAL_LOGS = (
    "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log",
    "RoboTrainerAID__za_experimental/candump.log",
    "hardbyte__python-can/test_CanMessage.asc",
)
TIME = {"frames": "t", "signals": "t", "sdo": "t", "events": "t", "findings": "t"}


def _undated(src: Path, dest: Path) -> None:
    """A candump log with times from the logger's start (no date: Hive's null partition)."""
    lines = src.read_text().splitlines()
    t0 = float(lines[0].split(")")[0][1:])
    out = [f"({float(ln.split(')')[0][1:]) - t0:.6f}){ln.split(')', 1)[1]}" for ln in lines]
    dest.write_text("\n".join(out) + "\n")


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> list[str]:
    folder = tmp_path_factory.mktemp("logs")
    for p in sorted(SAMPLES.glob("*.log")) + sorted(SAMPLES.glob("*.asc")):
        shutil.copy(p, folder / p.name)
    _undated(SAMPLES / "demo.log", folder / "undated.log")
    real = [str(REAL / r) for r in REAL_LOGS if (REAL / r).is_file()]
    return sorted(str(p) for p in folder.iterdir()) + real


@pytest.fixture(scope="module")
def dataset(logs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ds") / "ds"
    result = run_fleet(logs, out, workers=1)
    assert not result.failed
    return out


def test_pyarrow_reads_the_date_partition_as_a_date(dataset):
    found = ds.dataset(dataset / "frames", format="parquet", partitioning=schema.partitioning())
    assert found.schema.field("date").type == pa.date32()
    dates = set(found.to_table(columns=["date"]).column("date").to_pylist())
    assert None in dates and len(dates) >= 2  # the logs' days, and the undated log's null
    assert schema.dataset_schema("frames").field("date").type == pa.date32()


@pytest.mark.parametrize("only_undated", [False, True])
def test_duckdb_in_query_reads_the_date_partition_as_a_date(dataset, logs, tmp_path, only_undated):
    if only_undated:  # DuckDB alone would guess text for a `date=__HIVE_DEFAULT_PARTITION__`
        dataset = tmp_path / "undated"
        assert not run_fleet(
            [p for p in logs if p.endswith("undated.log")], dataset, workers=1
        ).failed
        glob = str(dataset / "logs" / "date=*" / "*.parquet")
        guessed = duckdb.sql(
            f"SELECT typeof(date) FROM read_parquet('{glob}', hive_partitioning = true)"
        ).fetchall()
        assert guessed == [("VARCHAR",)]
    con = query.connect(dataset)
    for table in schema.TABLES:
        types = {r[0]: r[1] for r in con.execute(f"DESCRIBE {table}").fetchall()}
        assert types["date"] == "DATE", table


def _files(dataset: Path, table: str) -> list[Path]:
    return sorted((dataset / table).glob("date=*/*.parquet"))


def _duckdb_counts(dataset: Path, table: str) -> Counter:
    """Rows per (date, log) of a table, as DuckDB reads the folder on its own."""
    glob = str(dataset / table / "date=*" / "*.parquet")
    rows = duckdb.sql(
        f"SELECT date, hash, count(*) FROM read_parquet('{glob}', hive_partitioning = true, "
        "union_by_name = true) GROUP BY ALL"
    ).fetchall()
    return Counter({(str(d), h): n for d, h, n in rows})


def _pyarrow_counts(dataset: Path, table: str) -> Counter:
    dates = ds.partitioning(pa.schema([("date", pa.date32())]), flavor="hive")
    t = ds.dataset(dataset / table, format="parquet", partitioning=dates).to_table(
        columns=["date", "hash", "source"]
    )
    return Counter(
        zip(t["date"].to_pylist(), t["hash"].to_pylist(), t["source"].to_pylist(), strict=True)
    )


def _compact(dataset: Path, *extra: str) -> None:
    assert main(["fleet", "compact", str(dataset), "-q", *extra]) == 0


def test_compact_keeps_every_row_and_its_lineage_in_fewer_time_ordered_files(dataset, tmp_path):
    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    before = {t: (_duckdb_counts(copy, t), _pyarrow_counts(copy, t)) for t in schema.TABLES}
    files = {t: len(_files(copy, t)) for t in schema.TABLES}
    _compact(copy)
    for table in schema.TABLES:
        assert (_duckdb_counts(copy, table), _pyarrow_counts(copy, table)) == before[table], table
        found = _files(copy, table)
        partitions = {p.parent for p in found}
        assert len(found) == len(partitions) < files[table], table  # one file a partition
        for part in found:  # a partition of one part before keeps it as it was
            if part.name.startswith("part-compact-") and table in TIME:
                t = pq.read_table(part, columns=[TIME[table]])[TIME[table]].drop_null()
                assert pc.all(pc.greater_equal(t[1:], t[:-1])).as_py() in (True, None), part
    assert not [p for p in (copy / "_staging").iterdir() if p.is_dir()]
    # a small target: several files a partition, each still time-ordered, rows kept
    small = tmp_path / "small"
    shutil.copytree(dataset, small)
    _compact(small, "--target-size", "20KB")
    assert _duckdb_counts(small, "frames") == before["frames"][0]
    assert len(_files(small, "frames")) > len({p.parent for p in _files(small, "frames")})
    # tables merge by size, so a log's logs part may stay loose beside its merged rows:
    # a run's reconcile (and another compaction) must keep them
    with compact.locked(small):
        compact.reconcile(small)
    _compact(small, "--target-size", "20KB")
    for table in schema.TABLES:
        assert _duckdb_counts(small, table) == before[table][0], table


def test_reruns_after_compact_skip_and_replace_by_rows_not_file_names(
    tmp_path, cluster, monkeypatch
):
    folder = tmp_path / "logs"
    folder.mkdir()
    for name in ("demo.log", "faults.log", "commissioning.log", "demo.asc"):
        shutil.copy(SAMPLES / name, folder / name)
    logs = sorted(str(p) for p in folder.iterdir())
    dataset = tmp_path / "ds"
    assert not run_fleet(logs, dataset, scheduler=cluster).failed
    _compact(dataset)
    assert all(len(_files(dataset, t)) == 1 for t in schema.TABLES)
    frames = _pyarrow_counts(dataset, "frames")

    # nothing changed: every log skipped from the compacted logs rows, no cluster
    real_client = orchestrate._client
    monkeypatch.setattr(orchestrate, "_client", lambda *a, **k: pytest.fail("a cluster"))
    again = run_fleet(logs, dataset, scheduler=cluster)
    assert len(again.skipped) == 4 and again.frames == 0
    monkeypatch.setattr(orchestrate, "_client", real_client)

    # touched, not changed: hashed by the worker, found in the compacted file, skipped
    os.utime(logs[0], ns=(1, 1))
    touched = run_fleet(logs, dataset, scheduler=cluster)
    assert len(touched.skipped) == 4 and touched.frames == 0
    assert _pyarrow_counts(dataset, "frames") == frames

    # a changed log: exactly its new rows, its old ones gone from the compacted file
    changed = folder / "demo.log"
    changed.write_text("".join(open(SAMPLES / "faults.log").readlines()[:150]))
    run = run_fleet(logs, dataset, scheduler=cluster)
    assert len(run.skipped) == 3 and run.frames == 150
    new_hash = task.content_hash(changed)
    for table in schema.TABLES:
        counts = _duckdb_counts(dataset, table)
        by_source = Counter()
        for (_, h, src), n in _pyarrow_counts(dataset, table).items():
            by_source[src, h] += n
        hashes = {h for (src, h) in by_source if src == str(changed)}
        assert hashes <= {new_hash}, table  # the old content's rows: none
        assert sum(counts.values()) == sum(by_source.values())
    rows = duckdb.sql(
        f"SELECT source, hash, frames FROM read_parquet('{dataset}/logs/date=*/*.parquet')"
    ).fetchall()
    assert sorted(r[0] for r in rows) == logs  # one row a log
    assert (str(changed), new_hash, 150) in rows
    assert (
        sum(n for (_, h, _), n in _pyarrow_counts(dataset, "frames").items() if h == new_hash)
        == 150
    )

    # --force: every log decoded again, no row twice, the compacted files emptied away
    forced = run_fleet(logs, dataset, scheduler=cluster, force=True)
    assert not forced.skipped
    assert all(n == 1 for n in _pyarrow_counts(dataset, "logs").values())
    assert not list(dataset.glob("*/date=*/part-compact-*.parquet"))
    assert sum(_duckdb_counts(dataset, "frames").values()) == sum(frames.values()) - 185 + 150


def test_compact_refuses_what_it_cannot_compact_in_one_line(tmp_path, capsys):
    assert main(["fleet", "compact", str(tmp_path)]) == 2
    with pytest.raises(SystemExit) as exit_:
        main(["fleet", "compact", str(tmp_path), "--target-size", "lots"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err.splitlines()
    assert f"cananalyze: error: {tmp_path}: not a fleet dataset (no logs table in it)" in err
    assert "not a size: 'lots'" in err[-1] and "Traceback" not in "".join(err)


def test_a_compaction_publishes_only_between_queries(dataset, tmp_path):
    """`query` holds the publish lock shared while it reads: a compaction's rename and
    removals wait for it (no row seen twice, no part removed under it)."""
    import threading

    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    before = len(_files(copy, "frames"))
    done = threading.Event()
    with compact.reading(copy):
        worker = threading.Thread(target=lambda: (compact.compact(copy), done.set()))
        worker.start()
        # only a broken lock can fail this: a slow machine just finishes later
        assert not done.wait(1.0)
        assert len(_files(copy, "frames")) == before
    worker.join()
    assert done.is_set() and len(_files(copy, "frames")) < before


@pytest.mark.slow  # a fleet run, then compaction, end to end
def test_fleet_compact_flag_compacts_the_days_a_run_wrote(tmp_path, capsys):
    folder = tmp_path / "logs"
    folder.mkdir()
    for name in ("demo.log", "faults.log", "demo.asc"):
        shutil.copy(SAMPLES / name, folder / name)
    _undated(SAMPLES / "faults.log", tmp_path / "undated.log")  # not in this run
    dataset = tmp_path / "ds"
    assert main(["fleet", str(tmp_path / "undated.log"), "--out", str(dataset), "-q"]) == 1
    base = ["fleet", str(folder), "--out", str(dataset), "--workers", "1", "--compact"]
    assert main(base) == 1  # the samples break rules: exit 1, as without --compact
    err = capsys.readouterr().err
    assert "compacted: 28 files in the dataset, now 14" in err  # the undated log's 7 kept
    undated = dataset / "frames" / "date=__HIVE_DEFAULT_PARTITION__"
    assert [p.name.startswith("part-") for p in undated.iterdir()] == [True]  # not this run's
    for table in schema.TABLES:
        (day,) = (dataset / table).glob("date=2026-*/*.parquet")
        assert day.name.startswith("part-compact-")
    shutil.copy(SAMPLES / "commissioning.log", folder / "commissioning.log")
    assert main(base) == 1
    counts = _duckdb_counts(dataset, "logs")
    assert len(counts) == 5 and set(counts.values()) == {1}
    assert len(list((dataset / "frames").glob("date=2026-*/*.parquet"))) == 1


@pytest.mark.parametrize("then", ["compact", "fleet"])
def test_a_compaction_cut_between_publish_and_removals_is_finished(
    dataset, logs, tmp_path, monkeypatch, then
):
    """Killed after its new file is in place, before its inputs are gone: the rows are
    there twice until the next `compact` or `fleet` finishes the stage's manifest (never
    the reconcile first, which would take the new file's rows for stale)."""
    from cananalyze.fleet import layout

    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    before = _duckdb_counts(copy, "frames")

    def killed(path, *a, **k):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(layout.os, "unlink", killed)
        with pytest.raises(KeyboardInterrupt):
            compact.compact(copy)
    assert sum(_duckdb_counts(copy, "frames").values()) > sum(before.values())  # the crash
    if then == "compact":
        compact.compact(copy)
    else:
        with compact.locked(copy):
            compact.reconcile(copy)  # what every fleet run does at its end
    assert _duckdb_counts(copy, "frames") == before


def test_reconcile_drops_compacted_rows_of_no_log(dataset, tmp_path):
    """A changed file's old rows merged by a compaction while the run that replaced them
    removed their parts: no logs row names them any more, and the next reconcile drops
    them (and nothing else)."""
    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    _compact(copy)
    before = _duckdb_counts(copy, "frames")
    (logs_file,) = [p for p in _files(copy, "logs") if "2026-01-01" in str(p)]
    rows = pq.read_table(logs_file)
    gone = rows["hash"][0].as_py()
    kept = rows.filter(pc.not_equal(rows["hash"].cast(pa.string()), gone))
    listed = sorted(set(kept["hash"].cast(pa.string()).to_pylist()))
    meta = {**rows.schema.metadata, compact.HASHES: json.dumps(listed).encode()}
    pq.write_table(kept.replace_schema_metadata(meta), logs_file)  # as a compaction writes
    with compact.locked(copy):
        assert compact.reconcile(copy) >= 5  # the data tables' files of that day
    after = _duckdb_counts(copy, "frames")
    assert after == Counter({k: n for k, n in before.items() if k[1] != gone})


def test_batched_small_logs_share_parts_with_the_same_rows(dataset, logs, tmp_path, cluster):
    """`--batch 4`: the small logs go four to a task and share their parts; every table
    holds the rows the one-log-a-task run wrote, a rerun skips them all, and a changed log
    of a batch leaves exactly its new rows."""
    batched = tmp_path / "batched"
    assert not run_fleet(logs, batched, scheduler=cluster, batch=4).failed
    for table in schema.TABLES:
        assert _duckdb_counts(batched, table) == _duckdb_counts(dataset, table), table
        assert len(_files(batched, table)) < len(_files(dataset, table))
    assert any(p.name.startswith("part-compact-") for p in _files(batched, "frames"))
    again = run_fleet(logs, batched, scheduler=cluster, batch=4)
    assert len(again.skipped) == len(logs)

    folder = tmp_path / "logs"
    folder.mkdir()
    for name in ("demo.log", "faults.log", "commissioning.log"):
        shutil.copy(SAMPLES / name, folder / name)
    mine = sorted(str(p) for p in folder.iterdir())
    ds_ = tmp_path / "ds"
    run_fleet(mine, ds_, scheduler=cluster, batch=4)
    assert len(_files(ds_, "frames")) == 1
    changed = folder / "demo.log"
    changed.write_text("".join(open(SAMPLES / "faults.log").readlines()[:150]))
    assert run_fleet(mine, ds_, scheduler=cluster, batch=4).frames == 150
    new = task.content_hash(changed)
    for table in schema.TABLES:
        by = _pyarrow_counts(ds_, table)
        assert {h for (_, h, s) in by if s == str(changed)} <= {new}, table
    assert sum(n for (_, h, _), n in _pyarrow_counts(ds_, "frames").items() if h == new) == 150
    assert len(_pyarrow_counts(ds_, "logs")) == 3


@pytest.mark.slow  # three batched fleet runs, end to end
def test_a_batch_decoded_again_leaves_no_earlier_copy_in_the_shared_files(tmp_path, cluster):
    """`--batch` merges a batch's parts into shared files: a batch decoded again (`--force`,
    or files changed) must first drop its logs' earlier rows from the shared files the
    last batch wrote; once the new rows are merged too, nothing tells the copies apart."""
    folder = tmp_path / "logs"
    folder.mkdir()
    for name in ("demo.log", "faults.log", "commissioning.log"):
        shutil.copy(SAMPLES / name, folder / name)
    mine = sorted(str(p) for p in folder.iterdir())
    ds_ = tmp_path / "ds"
    run_fleet(mine, ds_, scheduler=cluster, batch=4)
    first = {t: _pyarrow_counts(ds_, t) for t in schema.TABLES}
    assert run_fleet(mine, ds_, scheduler=cluster, batch=4, force=True).skipped == []
    for table in schema.TABLES:
        assert _pyarrow_counts(ds_, table) == first[table], table
    # two of the three files changed: their old content's rows go, the new ones come in
    lines = open(SAMPLES / "faults.log").readlines()
    (folder / "demo.log").write_text("".join(lines[:150]))
    (folder / "commissioning.log").write_text("".join(lines[:90]))
    assert run_fleet(mine, ds_, scheduler=cluster, batch=4).frames == 240
    frames = _pyarrow_counts(ds_, "frames")
    by_source = Counter()
    for (_, _, source), n in frames.items():
        by_source[source] += n
    assert by_source[str(folder / "demo.log")] == 150
    assert by_source[str(folder / "commissioning.log")] == 90
    assert len(_pyarrow_counts(ds_, "logs")) == 3
