"""One log, on a Dask worker: the same pipeline as `export --parquet`, committed into the dataset.

The task hashes the file, skips it when the dataset already holds that content
decoded by this cananalyze without failure (unless forced), runs `pipeline.run` into a
`TableSink` in its staging folder (the export's flat memory: nothing per frame
kept), conforms each table file to the fleet schema row group by row group with
the lineage columns appended (no second decode), and commits. It returns one
small dict (the `logs` row, the violations to list, the JUnit testsuite when
asked): the tables themselves never pass through the scheduler.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import resource
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from cananalyze.core import storage
from cananalyze.core.errors import CananalyzeError
from cananalyze.core.version import __version__
from cananalyze.fleet import layout, schema
from cananalyze.pipeline import Options
from cananalyze.pipeline.sink import Sink

# times at or after 2000-01-01 and before 2100 are wall-clock times; smaller ones count
# from the logger's start (candump without -t a, relative ASC): the file's name dates
# those when it holds a date (NAME_DATES), else the date is unknown (null). Never the
# modification time: a copy made today would land under today.
_EPOCH_FROM, _EPOCH_TO = 946_684_800.0, 4_102_444_800.0
UNKNOWN_DATE = layout.UNKNOWN_DATE  # Hive's partition of no value (fleet/layout.py)
# (pattern, groups as year, month, day): 2024-03-13 / 2024_03_13 / 20240313 anywhere in
# the name; Sevcon DVT's can_DDMMYY_HHMMSS (can_180209_154604: 18 Feb 2009)
NAME_DATES = (
    (re.compile(r"(?<!\d)(20\d\d)[-_]?(0[1-9]|1[0-2])[-_]?(0[1-9]|[12]\d|3[01])(?!\d)"), (1, 2, 3)),
    (re.compile(r"(?<!\d)(0[1-9]|[12]\d|3[01])(0[1-9]|1[0-2])(\d\d)_\d{6}(?!\d)"), (3, 2, 1)),
)
EXPORT = "export"  # the TableSink's folder inside the stage


@dataclass
class LogTask:
    """What a worker needs for one log (pickled to the worker: keep it small)."""

    path: str
    dataset: str
    opts: Options
    force: bool = False
    junit: bool = False
    compression: str = "snappy"
    extra: dict = field(default_factory=dict)  # room for later per-log settings
    timeout: float | None = None  # seconds before the log is given up (run_task)
    run: str = ""  # the fleet run's id, in the logs row: what this run wrote, retries included
    # the digests of the rows the dataset holds for this path (its earlier content): their
    # parts are removed when this log commits, so a changed file is never in it twice
    replaces: tuple[str, ...] = ()
    # the dates this log's earlier parts can be at (the driver's: those of the rows of
    # this path and of any content of this file's `size`): its parts there are named, not
    # listed (fleet/layout.parts_at). None: not known; every date folder is listed
    known: tuple[str, ...] | None = None
    size: int | None = None


class _Findings(Sink):
    """Counts the run's findings; keeps the Finding objects only for a JUnit report."""

    def __init__(self, keep: bool, cancel=None) -> None:
        self.keep = keep
        self.cancel = cancel  # run_task's Event: the time is up
        self.findings: list = []
        self.total = 0
        self.failing = 0
        self.first: dict[str, str] = {}  # rule -> its first failing message

    def write(self, batch) -> None:
        if self.cancel is not None and self.cancel.is_set():
            raise _Cancelled
        found = batch.findings  # columns: a message is built only for each rule's first
        if not len(found):
            return
        self.total += len(found)
        bad = np.flatnonzero(found.fails)
        self.failing += int(bad.size)
        rules = found.rule[bad].tolist()
        for rule, i in zip(rules, bad.tolist(), strict=True):
            if rule not in self.first:
                self.first[rule] = found.messages(np.array([i]))[0]
        if self.keep:
            self.findings.extend(found.findings())


def content_hash(path: str | Path, storage_options: dict | None = None) -> str:
    """sha256 of the file's bytes (as stored: a .gz is hashed compressed); a path or URL."""
    with storage.open_binary(path, storage_options) as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def options_digest(opts: Options) -> str:
    """sha256 of what decides a log's tables besides its bytes: the options and the
    content of every file they name (network, EDS, DBC, rules). It is part of the skip
    key, so a rerun with another network or rules file decodes the log again instead of
    keeping tables made under the old configuration."""

    def content(path) -> str | None:
        if path is None:
            return None
        try:
            return content_hash(path)
        except OSError:
            return f"unreadable:{path}"  # the decode itself will say what is wrong

    key = {
        "network": content(opts.network),
        "devices": sorted(opts.devices.items()),
        "eds": sorted((n, content(p)) for n, p in opts.eds.items()),
        "rules": content(opts.rules),
        "dbc": [content(p) for p in opts.dbc],
        **{k: getattr(opts, k) for k in _DECIDING},
        "nodes": sorted(opts.nodes) if opts.nodes is not None else None,
        "services": sorted(opts.services) if opts.services is not None else None,
    }
    return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()


# the plain options that change what is decoded or found (not how text is shown)
_DECIDING = (
    "checks",
    "timing",
    "sdo_timeout",
    "strict",
    "input_format",
    "bitrate",
    "t_from",
    "t_to",
)


def _parts_of(
    dataset: layout.Dataset, table: str, digest: str, options: dict | None, dates
) -> list:
    """A log's parts of `table`: at these `dates` (a task's `known`), or (None: not known)
    found by a glob over every date folder."""
    if dates is None:
        return layout.existing_parts(dataset, table, digest, options)
    return layout.parts_at(dataset, table, digest, dates)


def recorded(
    dataset: layout.Dataset, digest: str, options: dict | None = None, dates=None
) -> dict | None:
    """The dataset's `logs` row for this content (its own part, or a compacted file's), or
    None. `dates`: the partitions its rows are known to be in (no listing), else all."""
    import pyarrow.parquet as pq

    for part in _parts_of(dataset, "logs", digest, options, dates):
        with contextlib.suppress(OSError, ValueError):
            if isinstance(part, str):
                with layout.open_part(part, options) as f:
                    rows = pq.read_table(f).to_pylist()
            else:
                rows = pq.read_table(part).to_pylist()
            if rows:
                return rows[0]
    if isinstance(dataset, Path):  # compacted (`fleet compact`): the row is in a shared file
        from cananalyze.fleet.compact import compacted_row

        return compacted_row(dataset, digest)
    return None


def logs_rows(dataset: layout.Dataset, options: dict | None = None) -> dict[str, list[dict]] | None:
    """Every `logs` row of the dataset by source, read once (the driver's skip key, where
    the workers find a log's earlier parts, the run's counts), `date` as its folder names
    it; {} when there are none, None when they cannot be read (then every log is hashed
    and looked up by its worker: never a wrong skip). Through the dataset's index of its
    `logs` parts (fleet/logsindex): only the parts it does not hold yet are read."""
    from cananalyze.fleet.logsindex import logs_rows as rows_of

    rows = rows_of(dataset, options)
    if rows is None:
        return None
    out: dict[str, list[dict]] = {}
    for row in rows:
        row["date"] = layout.row_date(row["date"])
        out.setdefault(row["source"], []).append(row)
    return out


def unchanged(rows: list[dict], size: int | None, mtime_ns: int | None, config: str):
    """The recorded row that lets a log be skipped without reading it: decoded ok by this
    cananalyze under this configuration, from a file of this size and modification time
    at this path. None: the worker hashes it."""
    if mtime_ns is None:
        return None
    for row in rows:
        if (
            row.get("status") == "ok"
            and row.get("version") == __version__
            and row.get("config") == config
            and row.get("size") == size
            and row.get("mtime_ns") == mtime_ns
        ):
            return row
    return None


def _one_line(exc: BaseException, path: str, dataset: str | Path | None = None) -> str:
    if isinstance(exc, OSError) and dataset is not None:
        # a full disk (pyarrow's OSError names no file), or a write into the dataset: the
        # staging's inner path says nothing to the user, the dataset does
        where = str(exc.filename or "")
        if exc.errno in (errno.ENOSPC, errno.EDQUOT) or where.startswith(str(dataset)):
            why = os.strerror(exc.errno) if exc.errno else (exc.strerror or str(exc))
            return f"{path}: cannot write the dataset {dataset}: {why}"
    text = " ".join(str(exc).split()) or type(exc).__name__
    if not isinstance(exc, CananalyzeError):
        text = f"{type(exc).__name__}: {text}"  # not an input error we foresaw: say what
    return text if path in text else f"{path}: {text}"


def _date(t_first: float | None, path: str) -> tuple[str, str]:
    """(partition date, where it came from: "log", "name" or "unknown")."""
    if t_first is not None and _EPOCH_FROM <= t_first < _EPOCH_TO:
        return datetime.fromtimestamp(t_first, UTC).strftime("%Y-%m-%d"), "log"
    name = os.path.basename(str(path))
    for pattern, (y, m, d) in NAME_DATES:
        for match in pattern.finditer(name):
            year = int(match.group(y))
            year += 2000 if year < 100 else 0
            try:
                day = datetime(year, int(match.group(m)), int(match.group(d)), tzinfo=UTC)
            except ValueError:  # 31 February
                continue
            return day.strftime("%Y-%m-%d"), "name"
    return UNKNOWN_DATE, "unknown"


def _check_schema(path: Path, table: str) -> None:
    """A table as the export wrote it must be the dataset's (one schema per table)."""
    import pyarrow.parquet as pq

    if table not in schema.COLUMNS:
        raise ValueError(f"{table} table: not in the dataset's schema (cananalyze/fleet/schema.py)")
    got = pq.read_schema(path).remove_metadata()
    if not got.equals(schema.schema(table)):
        raise ValueError(f"{table} table: written as {got}, the dataset has {schema.schema(table)}")


def _logs_part(dest: Path, row: dict, lineage: dict) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = {c: pa.array([row.get(c)], t) for c, t in schema.COLUMNS["logs"]}
    table = schema.conform(pa.table(cols), "logs", lineage)
    pq.write_table(table, dest)


def _suite(path: str, rules, findings, error: str | None) -> str:
    """One JUnit testsuite for this log (check's report, or one failing `decode` case)."""
    if error is None:
        from cananalyze.outputs.junit import junit_xml

        suite = ET.fromstring(junit_xml(rules, findings, name=path).split("?>", 1)[-1])[0]
    else:
        suite = ET.Element("testsuite", name=path, tests="1", failures="0", errors="1")
        case = ET.SubElement(suite, "testcase", classname="cananalyze.decode", name="decode")
        ET.SubElement(case, "error", message=error, type="input").text = error
    return ET.tostring(suite, encoding="unicode")


class _Cancelled(BaseException):
    """The task's time is up: the decode stops at its next batch and commits nothing."""


def run_task(task: LogTask) -> dict:
    """`process` with the task's time limit (`task.timeout`, --task-timeout): a log that
    has not finished by then (an input that never ends, a read that hangs) becomes a
    `failed` row saying so, and the worker goes on with the next log.

    The log runs in a thread of its own, since a blocked read cannot be interrupted: when
    the time is up the thread is told to stop at its next batch and never to commit; one
    blocked for good stays parked until the worker process ends.
    """
    import threading

    if not task.timeout:
        return process(task)
    cancel = threading.Event()
    box: dict = {}

    def work() -> None:
        try:
            box["result"] = process(task, cancel)
        except BaseException as exc:  # noqa: BLE001 - handed to the calling thread
            box["error"] = exc

    thread = threading.Thread(target=work, name=f"cananalyze-log-{task.path}", daemon=True)
    thread.start()
    thread.join(task.timeout)
    if thread.is_alive():
        cancel.set()
        error = f"{task.path}: no result after {task.timeout:g} s (--task-timeout): given up"
        where = task.opts.storage_options
        return record_failure(task.dataset, task.path, error, where, False, task.run)
    if "error" in box:
        raise box["error"]
    return box["result"]


def run_batch(tasks: list[LogTask]) -> list[dict]:
    """Several small logs in one Dask task (`fleet --batch N`): each decoded and committed
    as `run_task` does, then the parts of those it wrote merged per table and date into
    shared files (compact.merge_logs; a local dataset's only). A merge that cannot be made
    (a full disk) leaves the logs' own parts: the dataset is whole either way."""
    results = [run_task(t) for t in tasks]
    dataset = layout.root(tasks[0].dataset)
    written = {r["hash"] for r in results if not r.get("skipped") and r.get("hash")}
    # each written log's path's earlier content (the driver's): its compacted rows go too
    mine = {r["source"] for r in results if not r.get("skipped") and r.get("hash")}
    old = {t.path: set(t.replaces) for t in tasks if t.path in mine and t.replaces}
    if isinstance(dataset, Path) and len(written) > 1:
        from cananalyze.fleet.compact import merge_logs

        with contextlib.suppress(OSError):
            merge_logs(dataset, written, tasks[0].compression, old)
    elif len(written) > 1:  # at a URL: the parts named from each log's date
        from cananalyze.fleet.compact import merge_remote_logs

        dated = {
            r["hash"]: (r["date"], r.get("status") == "ok")
            for r in results
            if not r.get("skipped") and r.get("hash") and r.get("date")
        }
        with contextlib.suppress(OSError):
            earlier = (
                None
                if any(t.known is None for t in tasks)
                else {d for t in tasks if t.path in mine for d in t.known}
            )
            merge_remote_logs(
                *(str(dataset), dated, tasks[0].compression, tasks[0].opts.storage_options),
                old=old,
                earlier=earlier,
            )
    return results


def _path_digest(path: str) -> str:
    """The part name of a log whose content was not hashed (unreadable, not a log)."""
    return hashlib.sha256(f"unreadable:{path}".encode()).hexdigest()


def process(task: LogTask, cancel=None) -> dict:
    """Decode one log into the dataset; the result row (never raises for a bad log).

    The log is opened (its format told from its head) before its content is hashed:
    a file that is no log (a 20 GB file of zeros) is refused without being read whole.
    `cancel` (a threading.Event, run_task's): once set, the decode stops and nothing
    is committed.
    """
    from cananalyze.pipeline import open_source
    from cananalyze.runtime import allocator

    allocator.tune()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    path, dataset, where = task.path, layout.root(task.dataset), task.opts.storage_options
    row: dict = {"status": "ok", "error": None, "frames": 0, "findings": 0, "violations": 0}
    row["run"] = task.run
    source = None
    try:
        st = storage.stat_of(path, where)  # before reading: a later change shows next time
        row["size"], row["mtime_ns"] = st.size, st.mtime_ns
        try:
            source = open_source(path, task.opts)
        except (KeyboardInterrupt, SystemExit):
            raise
        except BaseException as exc:  # noqa: BLE001 - not a log: a row, not hashed
            digest = _path_digest(path)
            row.update(status="failed", error=_one_line(exc, path, task.dataset))
        else:
            digest = content_hash(path, where)
    except OSError as exc:
        digest = _path_digest(path)
        row.update(status="failed", error=f"{path}: cannot read ({exc.strerror or exc})")
    lineage = {"source": path, "hash": digest, "version": __version__}  # schema.LINEAGE's order
    result = {"source": path, "hash": digest, "skipped": False, "first": {}, "junit": None}
    row["config"] = options_digest(task.opts)
    known = task.known if row.get("size") == task.size else None  # else changed since
    if row["status"] == "ok" and not task.force:
        old = recorded(dataset, digest, where, known)
        # a failure is tried again: it may have been the machine's (a worker lost)
        if (
            old is not None
            and old.get("version") == __version__
            and old.get("status") == "ok"
            and old.get("config") == row["config"]
        ):
            source.close()
            if old.get("source") == path and old.get("mtime_ns") != row.get("mtime_ns"):
                _restamp(dataset, digest, old, row, where, known)
            result.update(old, skipped=True)
            result["source"], result["recorded_source"] = path, old.get("source")
            return result
    try:
        stage = layout.stage(dataset, digest, where)
    except OSError as exc:  # no room even for the staging folder: the log fails, in one line
        if source is not None:
            source.close()
        row.update(status="failed", error=_one_line(exc, path, dataset))
        result.update(row)
        result.update(lineage, date=None, worker_pid=os.getpid())
        return result
    try:
        sink = _Findings(keep=task.junit, cancel=cancel)
        state, rules = (
            _decode(task, source, stage, lineage, sink, row) if source is not None else (None, [])
        )
        date, row["date_from"] = _date(state.t0 if state is not None else None, path)
        parts = _parts(stage, dataset, date, digest, row, path) if state is not None else []
        row["seconds"] = time.perf_counter() - wall0
        row["cpu_seconds"] = time.process_time() - cpu0
        row["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        if cancel is not None and cancel.is_set():
            raise _Cancelled
        try:
            old = _still_mine(dataset, task.replaces, path, where, known)
            _commit(stage, dataset, date, digest, parts, row, lineage, where, old, known)
        except OSError as exc:  # a full disk: this log fails, in one line, and the fleet goes on
            stage.close()
            row.update(status="failed", error=_one_line(exc, path, dataset))
            _commit_failure(dataset, date, digest, row, lineage, where, known)
    except BaseException:
        stage.close()
        raise
    result.update(row)
    result.update(lineage, first=sink.first, date=date, worker_pid=os.getpid())
    if task.junit:
        result["junit"] = _suite(path, rules, sink.findings, row["error"])
    return result


def _still_mine(
    dataset: layout.Dataset,
    digests: tuple[str, ...],
    path: str,
    options: dict | None,
    known: tuple[str, ...] | None = None,
) -> tuple[str, ...]:
    """Of the digests the driver saw for this path, those whose row still names it (another
    path with that same content may have written the row since: its parts stay)."""
    return tuple(
        d for d in digests if (recorded(dataset, d, options, known) or {}).get("source") == path
    )


def _restamp(
    dataset: layout.Dataset, digest: str, old: dict, row: dict, options: dict | None, dates=None
) -> None:
    """The recorded row of a file whose bytes are unchanged but whose modification time
    is not (touched, copied back, or recorded before mtime_ns was): its `logs` part
    rewritten with the new time, so the next rerun skips it without reading it again.
    Nothing else changes (not its run: this run did not decode it). Best effort."""
    parts = _parts_of(dataset, "logs", digest, options, dates)
    if isinstance(dataset, str) and dates is not None:  # named, not listed: those there
        fs = storage.filesystem(dataset, options)[0]
        parts = [p for p in parts if fs.exists(p)]
    if not parts:
        return
    try:
        stage = layout.stage(dataset, digest, options)
    except OSError:
        return
    try:
        staged = stage.dir / "logs.parquet"
        lineage = {c: old[c] for c, _ in schema.LINEAGE}
        _logs_part(staged, {**old, "mtime_ns": row.get("mtime_ns"), "size": row["size"]}, lineage)
        stage.commit([(staged, parts[0])], [])
    except OSError:
        stage.close()


def _decode(
    task: LogTask, source, stage: layout.Stage, lineage: dict, findings: _Findings, row: dict
):
    """`pipeline.run` of the opened log into the export's TableSink in the stage, writing
    the dataset's schema; (the Run, the rules) or (None, []) with the row marked failed."""
    from cananalyze.outputs.tables.stream import TableSink
    from cananalyze.pipeline import build_decoder, run
    from cananalyze.runtime.gcpolicy import fewer_collections

    try:
        row["format"] = getattr(getattr(source, "fmt", None), "name", None)
        # the sinks take the findings from the batches: the checker keeps none
        decoder = build_decoder(task.opts, keep_findings=False)
        conform = schema.Conform(lineage)
        tables = TableSink(
            stage.dir / EXPORT, "parquet", task.compression, constants=lineage, conform=conform
        )
        with fewer_collections():
            state = run(source, decoder, [tables, findings], task.opts)
    except (KeyboardInterrupt, SystemExit, _Cancelled):
        source.close()
        raise
    except BaseException as exc:  # noqa: BLE001 - one log's failure is a row, not the fleet's
        source.close()
        row.update(status="failed", error=_one_line(exc, task.path, task.dataset))
        return None, []
    row["skipped_lines"] = source.problems.count
    row.update(frames=state.frames, t_first=state.t0, t_last=state.t_last)
    row.update(findings=findings.total, violations=findings.failing)
    return state, decoder.checker.rules if decoder.checker is not None else []


def _parts(
    stage: layout.Stage, dataset: layout.Dataset, date: str, digest: str, row: dict, path: str
):
    """(staged file, final part path) of every table; none, with the row failed, when a
    table is not in the dataset's schema."""
    from cananalyze.outputs.tables.stream import TABLES

    parts = []
    try:
        for table in TABLES:
            staged = stage.dir / EXPORT / f"{table}.parquet"
            _check_schema(staged, table)
            parts.append((staged, layout.part_path(dataset, table, date, digest)))
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # noqa: BLE001 - as a decode failure: no parts
        row.update(status="failed", error=_one_line(exc, path, dataset))
        return []
    return parts


def _commit(
    stage,
    dataset: layout.Dataset,
    date: str,
    digest: str,
    parts: list,
    row: dict,
    lineage: dict,
    options: dict | None = None,
    replaces: tuple[str, ...] = (),
    known: tuple[str, ...] | None = None,
):
    """The logs row written last, the log's parts at other dates (an earlier run's) removed,
    and those of its path's earlier content (`replaces`: the digests of the rows the
    dataset held for this path; the failed row it had when it could not be read). Where
    those can be: at the dates `known` (the driver's), else at any date (listed)."""
    staged = stage.dir / "logs.parquet"
    _logs_part(staged, row, lineage)
    renames = [*parts, (staged, layout.part_path(dataset, "logs", date, digest))]
    final = {d for _, d in renames}
    removals = [
        p
        for table in schema.TABLES
        for p in _parts_of(dataset, table, digest, options, known)
        if p not in final
    ]
    for old in sorted({*replaces, _path_digest(lineage["source"])} - {digest}):
        for table in schema.TABLES:
            removals += _parts_of(dataset, table, old, options, known)
    stage.commit(renames, removals)


def _commit_failure(
    dataset: layout.Dataset,
    date: str,
    digest: str,
    row: dict,
    lineage: dict,
    options: dict | None = None,
    known: tuple[str, ...] | None = None,
) -> None:
    """The failed log's row alone, if the disk still takes it (else none: a rerun tries
    the log again, as any log without a row)."""
    try:
        stage = layout.stage(dataset, digest, options)
    except OSError:
        return
    try:
        _commit(stage, dataset, date, digest, [], row, lineage, options, known=known)
    except OSError:
        stage.close()


def record_failure(
    dataset: str | Path,
    path: str,
    error: str,
    options: dict | None = None,
    hash_it: bool = True,
    run: str = "",
) -> dict:
    """A `logs` row of status failed written by the driver, for a log whose worker was lost
    (killed for memory, crashed): the rest of the fleet goes on. `hash_it` False: under
    the path's digest, not the content's (a log that timed out may never end)."""
    dataset = layout.root(dataset)
    try:
        digest = content_hash(path, options) if hash_it else _path_digest(path)
    except OSError:
        digest = _path_digest(path)
    lineage = {"source": path, "hash": digest, "version": __version__}
    date, date_from = _date(None, path)
    row = {"status": "failed", "error": error, "frames": 0, "date_from": date_from, "run": run}
    stage = layout.stage(dataset, digest, options)
    try:
        _commit(stage, dataset, date, digest, [], row, lineage, options)
    except BaseException:
        stage.close()
        raise
    return {**row, **lineage, "skipped": False, "first": {}, "junit": None, "date": date}
