"""The fleet run: inputs expanded, one Dask task per log, progress, the verdict and the JUnit report.

By default a local `dask.distributed` cluster of worker processes (one thread
each: a log's pipeline already keeps two cores busy with its reader and writer
threads) bound to 127.0.0.1, dashboard included; `scheduler` joins an existing
cluster instead (its workers must see the same paths). The driver holds one
small dict per log; the workers write the tables.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
import time
import uuid
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TextIO

from cananalyze.core.defaults import TASK_TIMEOUT
from cananalyze.core.errors import UsageError
from cananalyze.core.extras import need_installed
from cananalyze.fleet import compact, layout
from cananalyze.fleet.inputs import expand, options_for
from cananalyze.fleet.task import (
    LogTask,
    logs_rows,
    options_digest,
    record_failure,
    recorded,
    run_batch,
    run_task,
    unchanged,
)
from cananalyze.pipeline import Options


@dataclass
class FleetResult:
    """Every log's result row (input order), and what the run says about them."""

    results: list[dict]
    seconds: float = 0.0
    dashboard: str | None = None
    scheduler: str | None = None  # the scheduler's address (tcp://127.0.0.1:PORT when local)
    workers: list[str] = field(default_factory=list)  # the workers' addresses at the start
    recovered: tuple[int, int] = (0, 0)
    notes: list[str] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)  # inputs left out, one line each

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.results if r.get("status") == "failed"]

    @property
    def violated(self) -> list[dict]:
        return [r for r in self.results if r.get("status") == "ok" and r.get("violations")]

    @property
    def skipped(self) -> list[dict]:
        return [r for r in self.results if r.get("skipped")]

    @property
    def frames(self) -> int:
        return sum(int(r.get("frames") or 0) for r in self.results if not r.get("skipped"))

    @property
    def exit_code(self) -> int:
        """0: every log decoded, no rule violated; 1: a log failed, was refused or had
        violations."""
        return 1 if self.failed or self.violated or self.refused else 0


def _regular_files(
    logs: list[str], options: dict | None, infos: dict
) -> tuple[list[tuple[str, object]], list[str]]:
    """([(log, its core/storage.Stat)] of the regular files, a line for each input
    refused): a FIFO or a device named on the command line would block its worker or
    never end."""
    from cananalyze.core import storage

    kept, refused = [], []
    for log in logs:
        try:
            st = storage.stat_of(log, options, infos.get(log))
        except OSError as exc:
            refused.append(f"{log}: cannot read ({exc.strerror or exc})")
            continue
        if st.regular:
            kept.append((log, st))
        else:
            refused.append(f"{log}: not a regular file (a {st.kind}), left out")
    return kept, refused


def _make_dataset(dataset: layout.Dataset, options: dict | None) -> None:
    """The dataset folder made (a URL's: its bucket must be there), or one-line UsageError."""
    if isinstance(dataset, Path):
        try:
            dataset.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UsageError(
                f"{dataset}: cannot create the dataset folder ({exc.strerror})"
            ) from None
        return
    from cananalyze.core import storage

    fs, path = storage.filesystem(dataset, options)
    try:
        if fs.isfile(path):
            raise UsageError(f"{dataset}: exists and is not a dataset folder")
        fs.makedirs(path, exist_ok=True)  # object storage: the bucket, when it can
    except OSError as exc:
        raise UsageError(
            f"{dataset}: cannot reach the dataset: {' '.join(str(exc).split())}"
        ) from None


def _scratch(dataset: layout.Dataset):
    """The local cluster's scratch space: a stage of a local dataset (removed with it), or
    a local temporary folder's when the dataset is at a URL."""
    if isinstance(dataset, Path):
        return layout.Stage(dataset, layout.SCRATCH)
    return _TempScratch()


class _TempScratch:
    """A local temporary folder, removed whole when closed."""

    def __init__(self) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="cananalyze-fleet-"))

    def close(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)


def _client(workers: int | None, scheduler: str | None, scratch: Path | None = None):
    """A distributed Client: the existing scheduler's, or a local cluster's on 127.0.0.1,
    whose workers' scratch space is `scratch` (in the dataset's staging: removed with it,
    never a dask-scratch-space left in the temporary folder)."""
    from distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler), None
    import dask

    # the scheduler's and nannies' scratch too, not only the workers': set while the
    # cluster starts, so the caller's own Dask configuration is left as it was
    where = {"temporary-directory": str(scratch)} if scratch is not None else {}
    with dask.config.set(where):
        cluster = LocalCluster(
            local_directory=str(scratch) if scratch is not None else None,
            n_workers=workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address="127.0.0.1:0",
            silence_logs=logging.ERROR,
        )
    return Client(cluster), cluster


def _dashboard(client) -> str | None:
    try:
        if "dashboard" not in client.scheduler_info().get("services", {}):
            return None
        return client.dashboard_link
    except Exception:  # noqa: BLE001 - a report line, not the run
        return None


class _Progress:
    """Logs done of all, frames decoded, failures: on a terminal, the bar of
    outputs/progress.py (after its delay; cleared before the results), else nothing."""

    def __init__(self, stream: TextIO | None, total: int) -> None:
        self.bar = None
        self.frames = self.failed = 0
        if stream is None or not stream.isatty():
            return
        from cananalyze.outputs.progress import DelayedBar, terminal_bar

        def columns() -> list:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                TextColumn,
                TimeRemainingColumn,
            )

            return [
                TextColumn("logs"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("{task.fields[frames]:,} frames, {task.fields[failed]} failed"),
                TimeRemainingColumn(),
            ]

        self.bar = DelayedBar(
            terminal_bar(stream, columns),
            lambda bar: bar.add_task("logs", total=total, frames=0, failed=0),
        )

    def done(self, result: dict) -> None:
        if self.bar is None:
            return
        if not result.get("skipped"):
            self.frames += int(result.get("frames") or 0)
        self.failed += result.get("status") == "failed"
        self.bar.update(advance=1, frames=self.frames, failed=self.failed)

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.clear()


def run_fleet(
    inputs: list[str],
    dataset: str | Path,
    opts: Options | None = None,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    junit: str | None = None,
    compression: str = "snappy",
    stream: TextIO | None = None,
    storage_options: dict | None = None,
    task_timeout: float | None = TASK_TIMEOUT,
    compact_to: int | None = None,
    batch: int = 1,
) -> FleetResult:
    """Decode every log the inputs name into `dataset`; the results (nothing raised for a
    bad log). Inputs and the dataset may be URLs (s3://..., core/storage), reached with
    `storage_options` (fsspec's) and the environment's credentials. `stream`: where the
    dashboard line and the progress bar go. MissingExtra without the fleet extra, before
    the dataset folder is made. Inputs that are no regular files (a FIFO, a device) are
    refused, one line each, and the rest go on; a log not done after `task_timeout`
    seconds is a failed row. `compact_to` (bytes): the date partitions this run wrote are
    compacted at its end (fleet/compact.py), a local dataset's only. `batch` > 1: logs
    under BATCH_SMALL bytes go `batch` to a task, their parts merged into shared files
    (task.run_batch)."""
    need_installed("distributed", "fleet", "fleet")  # imported only when a cluster starts
    t0 = time.perf_counter()
    opts = opts or Options(checks=True)
    if not opts.checking:
        opts = replace(opts, checks=True)  # the findings table is a promise
    if storage_options:
        opts = replace(opts, storage_options=storage_options)
    where = opts.storage_options
    dataset = layout.root(dataset)
    if isinstance(dataset, Path) and dataset.exists() and not dataset.is_dir():
        raise UsageError(f"{dataset}: exists and is not a directory")
    infos: dict = {}
    logs, refused = _regular_files(expand(inputs, dataset, where, infos), where, infos)
    if not logs:
        raise UsageError("; ".join(refused) or f"no log files in {' '.join(inputs)}")
    if workers is not None and workers < 1:
        raise UsageError(f"--workers must be 1 or more (got {workers})")
    if batch < 1:
        raise UsageError(f"--batch must be 1 or more (got {batch})")
    if task_timeout is not None and not task_timeout > 0:
        raise UsageError(f"--task-timeout must be positive (got {task_timeout})")
    _make_dataset(dataset, where)
    if junit:
        from cananalyze.core.atomic import check_writable

        check_writable(junit)
    recovered = layout.recover(dataset, where)
    root = str(dataset.resolve()) if isinstance(dataset, Path) else dataset.rstrip("/")
    run = uuid.uuid4().hex
    out = FleetResult([], recovered=recovered, refused=refused)
    each = _OptionsByFolder(opts)
    by_path, earlier, known = _unchanged_logs(logs, dataset, each, force)
    tasks = []
    for p, st in logs:
        if p not in by_path:
            o, old = each(p), earlier.get(p, ())
            tasks.append(
                LogTask(
                    *(p, root, o, force, bool(junit), compression),
                    timeout=task_timeout,
                    run=run,
                    replaces=old,
                    known=known(p, st.size),
                    size=st.size,
                )
            )
    if tasks:
        sizes = {p: getattr(st, "size", 0) or 0 for p, st in logs}
        groups = _batches(tasks, sizes, batch)
        _on_cluster(groups, by_path, out, dataset, workers, scheduler, stream, run)
        _recount(by_path, tasks, layout.root(root), where, run)
    else:
        out.notes.append("nothing to decode (every log unchanged in the dataset): no cluster")
    if isinstance(dataset, Path):  # rows this run (or one cut short) replaced, out of
        with compact.locked(dataset):  # compacted files (fleet/compact.py)
            compact.reconcile(dataset, compression)
    elif tasks and (
        force or any(t.replaces or t.known is None or t.known for t in tasks) or recovered[0]
    ):
        # at a URL only when a log this run wrote may have rows in a compacted file (its
        # path or content of its size was recorded): else a listing of the whole dataset
        compact.reconcile_remote(dataset, compression, where)
    if compact_to:
        dates = {r["date"] for r in by_path.values() if not r.get("skipped") and r.get("date")}
        if dates:
            done = compact.compact(dataset, compact_to, compression, dates, where)
            out.notes.append(
                f"compacted: {len(done.sizes_before)} files in the dataset, now "
                f"{len(done.sizes_after)}"
            )
    if tasks:  # the parts this run wrote into the `logs` index: the next rerun reads none
        logs_rows(dataset, where)
    out.results = [by_path[p] for p, _ in logs if p in by_path]
    out.seconds = time.perf_counter() - t0
    if junit:
        _write_junit(junit, out.results)
    return out


class _OptionsByFolder:
    """`options_for` once per folder (a folder's network.toml is looked for once), and the
    configuration digest once per distinct options."""

    def __init__(self, opts: Options) -> None:
        self.opts = opts
        self._folders: dict[str, Options] = {}
        self._digests: dict[str, str] = {}

    def __call__(self, log: str) -> Options:
        folder = log.rsplit("/", 1)[0]
        if folder not in self._folders:
            self._folders[folder] = options_for(log, self.opts)
        return self._folders[folder]

    def digest(self, log: str) -> str:
        o = self(log)
        key = str(o.network)  # the only option a folder changes
        if key not in self._digests:
            self._digests[key] = options_digest(o)
        return self._digests[key]


def _unchanged_logs(
    logs: list[tuple[str, object]], dataset: layout.Dataset, each: _OptionsByFolder, force: bool
):
    """({path: result} of the logs the dataset holds unchanged, {path: digests of the rows
    it holds for each other one}, known(path, size): the rows a worker needs to find that
    log's earlier parts): decided from each file's path, size and modification time and
    the configuration, before any file is read; the rest go to the workers, which hash
    them (and replace those rows' parts when the content changed).

    `known` gives a task the dates its earlier parts can be at: those of its path's rows
    and of the rows of any content of its size (the content it will hash, if recorded,
    is among them). The worker then names the parts it replaces at those dates instead
    of listing every date folder of every table (on object storage, LISTs per commit
    that grew with the dataset). None when the `logs` table could not be read, or an ok
    row has no size (written before sizes were recorded): the worker lists instead."""
    rows = logs_rows(dataset, each.opts.storage_options)
    by_size: dict[int, set[str]] = {}
    exact = rows is not None
    for mine in (rows or {}).values():
        for row in mine:
            if row.get("size") is not None:
                by_size.setdefault(row["size"], set()).add(row["date"])
            elif row.get("status") == "ok":
                exact = False

    def known(path: str, size: int | None) -> tuple[str, ...] | None:
        if not exact or size is None:
            return None
        mine = {r["date"] for r in rows.get(path, ())}
        return tuple(sorted(mine | by_size.get(size, set())))

    rows = rows or {}
    done: dict[str, dict] = {}
    earlier: dict[str, tuple[str, ...]] = {}
    for path, st in logs:
        mine = rows.get(path, [])
        old = None if force else unchanged(mine, st.size, st.mtime_ns, each.digest(path))
        if old is not None:
            done[path] = {**old, "source": path, "skipped": True, "first": {}, "junit": None}
        elif mine:
            earlier[path] = tuple(sorted({r["hash"] for r in mine}))
    return done, earlier, known


# a log this small is batched with others by `fleet --batch N`: its seven parts would
# be kilobytes each (the median log's are 6 KB); a bigger one is a task and a part alone
BATCH_SMALL = 16 << 20


def _batches(tasks: list[LogTask], sizes: dict[str, int], batch: int) -> list[list[LogTask]]:
    """The tasks as Dask tasks: each alone, or (batch > 1) the small logs `batch` at a time."""
    if batch <= 1:
        return [[t] for t in tasks]
    small = [t for t in tasks if sizes.get(t.path, 0) < BATCH_SMALL]
    out = [[t] for t in tasks if sizes.get(t.path, 0) >= BATCH_SMALL]
    return out + [small[i : i + batch] for i in range(0, len(small), batch)]


def _on_cluster(
    groups: list[list[LogTask]],
    by_path: dict[str, dict],
    out: FleetResult,
    dataset: layout.Dataset,
    workers: int | None,
    scheduler: str | None,
    stream: TextIO | None,
    run: str,
) -> None:
    """The tasks run on the local cluster (started here, closed at the end) or the
    scheduler's; each result into `by_path`, a lost worker's log a failed row."""
    tasks = [t for g in groups for t in g]
    where = tasks[0].opts.storage_options
    scratch = None if scheduler else _scratch(dataset)
    try:
        client, cluster = _client(workers, scheduler, scratch.dir if scratch else None)
    except BaseException:
        if scratch is not None:
            scratch.close()
        raise
    progress = None
    try:
        out.dashboard = _dashboard(client)
        out.scheduler = client.scheduler.address
        if cluster is not None:
            client.wait_for_workers(len(cluster.workers))
        out.workers = sorted(client.scheduler_info().get("workers", {}))
        if stream is not None:
            link = out.dashboard or 'not running (needs bokeh: pip install "cananalyze[fleet]")'
            print(f"fleet: {len(tasks)} logs, dashboard {link}", file=stream)
        from distributed import as_completed

        if all(len(g) == 1 for g in groups):
            futures = client.map(run_task, [g[0] for g in groups], pure=False)
        else:
            futures = client.map(run_batch, groups, pure=False)
        paths_of = {f.key: [t.path for t in g] for f, g in zip(futures, groups, strict=True)}
        progress = _Progress(stream, len(tasks))
        for fut in as_completed(futures):
            try:
                results = fut.result()
                results = results if isinstance(results, list) else [results]
            except Exception as exc:  # noqa: BLE001 - a worker lost (memory, crash): its logs fail
                results = [_lost(dataset, p, exc, where, run) for p in paths_of[fut.key]]
            for result in results:
                by_path[result["source"]] = result
                progress.done(result)
            fut.release()
    finally:
        if progress is not None:
            progress.stop()
        client.close()
        if cluster is not None:
            cluster.close()
        if scratch is not None:
            scratch.close()


def _lost(dataset: layout.Dataset, path: str, exc: BaseException, where, run: str) -> dict:
    """A log whose task's worker was lost: failed, unless this run's row for it is there
    (a batch's worker lost after committing some of its logs keeps them)."""
    from cananalyze.fleet.task import content_hash

    try:
        row = recorded(dataset, content_hash(path, where), where)
    except OSError:
        row = None
    if row is not None and row.get("run") == run and row.get("source") == path:
        return {**row, "skipped": False, "first": {}, "junit": None}
    return record_failure(dataset, path, f"{path}: worker failed: {exc}", where, run=run)


def _recount(
    by_path: dict[str, dict], tasks: list[LogTask], dataset, options: dict | None, run: str
) -> None:
    """The run's results as the dataset's own `logs` rows say: a log whose row this run
    wrote was decoded (or failed) by it, even when Dask ran its task again after a lost
    result and the second run found the first one's row ("already in the dataset").
    Only a result that says "skipped" can be wrong so: only those rows are read."""
    for t in tasks:
        result = by_path.get(t.path)
        if result is None or not result.get("skipped") or not result.get("hash"):
            continue
        row = recorded(dataset, result["hash"], options, t.known)  # where the worker looked
        if row is not None and row.get("run") == run and row.get("source") == t.path:
            keep = {k: result[k] for k in ("first", "junit") if k in result}
            by_path[t.path] = {**row, **keep, "source": t.path, "skipped": False}


def _write_junit(dest: str, results: list[dict]) -> None:
    """One testsuite per log (a skipped log's: its recorded verdict, no cases)."""
    import xml.etree.ElementTree as ET

    from cananalyze.core.atomic import write_text_atomic

    root = ET.Element("testsuites", name="cananalyze fleet")
    for r in results:
        if r.get("junit"):
            root.append(ET.fromstring(r["junit"]))
        else:
            failed = r.get("status") == "failed"
            suite = ET.SubElement(root, "testsuite", name=r["source"], tests="1")
            suite.set("failures", "0")
            suite.set("errors", "1" if failed else "0")
            case = ET.SubElement(suite, "testcase", classname="cananalyze.fleet", name="recorded")
            if failed:
                ET.SubElement(case, "error", message=r.get("error") or "failed")
            elif r.get("violations"):
                suite.set("failures", "1")
                ET.SubElement(case, "failure", message=f"{r['violations']} violation(s) recorded")
            else:
                ET.SubElement(case, "skipped", message="already in the dataset")
    ET.indent(root)
    write_text_atomic(dest, ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n")


def summary_lines(out: FleetResult) -> list[str]:
    """The end of a run: counts, then every failed log and every log with violations."""
    done = len(out.results) - len(out.skipped)
    lines = [
        f"fleet: {len(out.results)} logs ({done} decoded, {len(out.skipped)} already in the "
        f"dataset), {out.frames:,} frames, {len(out.failed)} failed, "
        f"{len(out.violated)} with violations, {out.seconds:.1f} s"
        + "".join(f"; {note}" for note in out.notes)
    ]
    if any(out.recovered):
        lines.append(
            f"fleet: finished {out.recovered[0]} and undid {out.recovered[1]} interrupted commits"
        )
    for line in out.refused:
        lines.append(f"refused: {line}")
    for r in out.failed:
        lines.append(f"failed: {r.get('error') or r['source']}")
    for r in out.violated:
        rules = ", ".join(sorted(r.get("first") or {})) or "see the findings table"
        lines.append(f"violations: {r['source']}: {r['violations']} ({rules})")
    return lines
