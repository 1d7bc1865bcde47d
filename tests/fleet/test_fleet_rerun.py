"""Cheap reruns and honest counts (issue 39 items 3 and 5): the skip key is the file's
path, size, modification time and the configuration, decided before any byte is read;
only new or changed files are hashed, by the workers; a rerun with nothing to do starts
no cluster; the summary counts what the dataset's own `logs` rows say this run did."""

from __future__ import annotations

import os
import shutil
from collections import Counter
from pathlib import Path

import pyarrow as pa
import pyarrow.dataset as ds
import pytest

from cananalyze.fleet import orchestrate, task
from cananalyze.fleet.orchestrate import run_fleet, summary_lines
from cananalyze.pipeline import Options

SAMPLES = Path(__file__).resolve().parents[2] / "samples"
DATES = ds.partitioning(pa.schema([("date", pa.date32())]), flavor="hive")


def _logs(dataset: Path) -> list[dict]:
    return ds.dataset(dataset / "logs", format="parquet", partitioning=DATES).to_table().to_pylist()


@pytest.fixture
def logs(tmp_path) -> list[str]:
    folder = tmp_path / "logs"
    folder.mkdir()
    for name in ("demo.log", "demo.asc", "faults.log"):
        shutil.copy(SAMPLES / name, folder / name)
    return [str(folder / n) for n in ("demo.asc", "demo.log", "faults.log")]


@pytest.fixture
def hashed(monkeypatch) -> list[str]:
    """Every file whose content is hashed, by whom (worker threads share this process)."""
    seen: list[str] = []
    real = task.content_hash

    def counting(path, *a, **k):
        seen.append(str(path))
        return real(path, *a, **k)

    monkeypatch.setattr(task, "content_hash", counting)
    return seen


def test_a_rerun_with_nothing_to_do_reads_nothing_and_starts_no_cluster(
    tmp_path, logs, hashed, monkeypatch
):
    dataset = tmp_path / "ds"
    first = run_fleet(logs, dataset, workers=1)
    assert not first.skipped and len(_logs(dataset)) == 3
    hashed.clear()

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started for a rerun with nothing to do")

    monkeypatch.setattr(orchestrate, "_client", no_cluster)
    again = run_fleet(logs, dataset, workers=1)
    assert len(again.skipped) == 3 and again.frames == 0 and hashed == []
    assert again.scheduler is None
    assert again.exit_code == first.exit_code  # the recorded violations still count
    line = summary_lines(again)[0]
    assert "(0 decoded, 3 already in the dataset)" in line and "no cluster" in line
    rows = _logs(dataset)
    assert len(rows) == 3 and all(r["mtime_ns"] == os.stat(r["source"]).st_mtime_ns for r in rows)


def test_only_new_or_changed_files_are_hashed_and_by_the_workers(tmp_path, logs, hashed, cluster):
    dataset = tmp_path / "ds"
    run_fleet(logs, dataset, scheduler=cluster)
    hashed.clear()
    touched, changed, same = logs[0], logs[1], logs[2]
    st = os.stat(touched)
    os.utime(touched, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))  # same bytes
    with open(changed, "a") as f:
        f.write("(1700000000.000000) can0 701#05\n")  # one more frame
    again = run_fleet(logs, dataset, scheduler=cluster)
    assert sorted(hashed) == sorted([touched, changed])
    by_source = {r["source"]: r for r in again.results}
    assert by_source[same]["skipped"] and by_source[touched]["skipped"]
    assert not by_source[changed]["skipped"] and by_source[changed]["frames"] == 186
    assert "(1 decoded, 2 already in the dataset)" in summary_lines(again)[0]
    # the touched file's row has its new time now: the next rerun reads nothing at all
    hashed.clear()
    third = run_fleet(logs, dataset, scheduler=cluster)
    assert hashed == [] and len(third.skipped) == 3 and "no cluster" in summary_lines(third)[0]
    # one row per file, and the changed file's frames once: its old content's parts gone
    rows = _logs(dataset)
    assert sorted(r["source"] for r in rows) == sorted(logs)
    frames = ds.dataset(dataset / "frames", format="parquet", partitioning=DATES).to_table()
    per_source = Counter(frames.column("source").to_pylist())
    assert per_source == {r["source"]: r["frames"] for r in rows}
    assert per_source[changed] == 186
    # another configuration: nothing is unchanged, each log is hashed and decoded again
    hashed.clear()
    other = run_fleet(logs, dataset, Options(checks=True, sdo_timeout=0.5), scheduler=cluster)
    assert not other.skipped and sorted(hashed) == sorted(logs)


def test_a_task_dask_runs_twice_is_counted_as_decoded_once(tmp_path, logs, cluster, monkeypatch):
    """Dask runs a task again when its result is lost (a worker gone after finishing):
    the second run finds the first one's row. The summary counts the log as decoded by
    this run, with its frames, because the dataset's row says this run wrote it."""
    real = task.run_task

    def lost_then_rerun(t):
        real(t)  # the first result, lost on the way to the scheduler
        return real(t)

    monkeypatch.setattr(orchestrate, "run_task", lost_then_rerun)
    dataset = tmp_path / "ds"
    result = run_fleet(logs[:1], dataset, scheduler=cluster)
    (row,) = _logs(dataset)
    assert not result.skipped and result.frames == row["frames"] > 0
    assert "(1 decoded, 0 already in the dataset)" in summary_lines(result)[0]
    assert f"{row['frames']:,} frames" in summary_lines(result)[0]


@pytest.fixture
def parts_read(monkeypatch) -> list[str]:
    """Every `logs` part the driver reads itself (fleet/logsindex: the index holds the rest)."""
    from cananalyze.fleet import logsindex

    seen: list[str] = []
    real = logsindex._read_parts

    def counting(dataset, store, tags):
        seen.extend(sorted(tags.values()))
        return real(dataset, store, tags)

    monkeypatch.setattr(logsindex, "_read_parts", counting)
    return seen


@pytest.fixture
def opened() -> list[str]:
    """Every file Python opens from now on (an audit hook: the readers, hashing, pyarrow's
    Python-side opens), for the test's own filtering."""
    import sys

    seen: list[str] = []
    active = [True]

    def hook(event, args):
        if active[0] and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
            seen.append(os.fsdecode(args[0]))

    sys.addaudithook(hook)  # hooks cannot be removed: switched off after the test
    yield seen
    active[0] = False


def test_a_rerun_with_nothing_to_do_reads_no_log_and_no_logs_part(
    tmp_path, logs, cluster, hashed, parts_read, opened, monkeypatch
):
    """The run that decoded the logs leaves their `logs` rows in the dataset's index; a
    rerun with nothing to do then reads the index alone: no input opened or hashed, no
    `logs` part read, no cluster. A new log: the run reads its part once, at its end."""
    dataset = tmp_path / "ds"
    run_fleet(logs[:2], dataset, scheduler=cluster)
    assert (dataset / "_index" / "logs.parquet").is_file()
    parts_read.clear()
    hashed.clear()
    opened.clear()

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started for a rerun with nothing to do")

    with monkeypatch.context() as m:
        m.setattr(orchestrate, "_client", no_cluster)
        again = run_fleet(logs[:2], dataset, scheduler=cluster)
    assert (
        len(again.skipped) == 2
        and again.scheduler is None
        and "no cluster" in (summary_lines(again)[0])
    )
    assert parts_read == [] and hashed == []
    assert not [p for p in opened if p in logs or "/logs/date=" in p], opened
    # a third log: decoded, and its `logs` part read once by the run that wrote it
    third = run_fleet(logs, dataset, scheduler=cluster)
    assert [r["source"] for r in third.results if not r["skipped"]] == [logs[2]]
    assert logs[2] in opened  # the hook sees a log read (hashed, decoded)
    (part,) = parts_read
    assert part.startswith("date=") and part.endswith(".parquet")
    parts_read.clear()
    assert len(run_fleet(logs, dataset, scheduler=cluster).skipped) == 3 and parts_read == []


def test_the_index_is_never_trusted_over_the_parts(tmp_path, logs, cluster, parts_read):
    """A stale index (each part rewritten since: another configuration decoded the logs
    again) or a broken one: its rows are not taken, the parts are read, the rerun
    decodes what the dataset's own rows say it must."""
    dataset = tmp_path / "ds"
    index = dataset / "_index" / "logs.parquet"
    run_fleet(logs, dataset, scheduler=cluster)
    stale = index.read_bytes()  # rows saying: decoded under the default configuration
    other = Options(checks=True, sdo_timeout=0.5)
    assert not run_fleet(logs, dataset, other, scheduler=cluster).skipped
    index.write_bytes(stale)
    parts_read.clear()
    # the parts are the other configuration's: under the default one, every log again
    again = run_fleet(logs, dataset, scheduler=cluster)
    assert not again.skipped and len(parts_read) >= 3
    assert len(_logs(dataset)) == 3
    index.write_bytes(b"not parquet")
    parts_read.clear()
    rerun = run_fleet(logs, dataset, scheduler=cluster)
    assert len(rerun.skipped) == 3 and len(parts_read) == 3
    parts_read.clear()
    assert len(run_fleet(logs, dataset, scheduler=cluster).skipped) == 3 and parts_read == []
