"""The dataset on disk: `DATASET/<table>/date=YYYY-MM-DD/part-<hash>.parquet`, and how a log's
parts are committed so that no reader ever sees half a log.

A task writes everything into its own staging folder `DATASET/_staging/<name>/`
(underscore: Spark, `pyarrow.dataset` and our DuckDB globs skip it), holding an
exclusive lock on `.lock` while it works. To commit, it writes `COMMIT.json`
(the renames and removals to make, atomically), then renames each part
into place (the `logs` part last), then removes the folder. A crash or Ctrl-C
before COMMIT.json leaves only a staging folder, rolled back by the next run; one
after it is rolled forward by the next run ("a rerun finishes what was
interrupted"). A staging folder whose lock is held belongs to a live run and is
left alone, so two runs can share a dataset: each part is one rename, and two
runs that decode the same log write the same part.

The lock is `fcntl.flock`, which a local file system honours; on NFS give each
run its own dataset or run one at a time.

A dataset at a URL (`s3://bucket/ds`, core/storage) has no rename and no lock: the
task writes its parts into a local temporary folder, uploads them under
`DATASET/_staging/<name>/`, writes `COMMIT.json` there last (the copies and removals
to make), then copies each part to its place (the `logs` part last) and deletes the
staged objects (one bulk delete). Where a log's earlier parts are comes from the
`logs` rows the driver read (`parts_at`), not from a listing of every date folder. A run's `recover` finishes (manifest there) or deletes (none) what an
interrupted run left, as for a local dataset; with no lock to tell a live run's stage
from a dead one, run one fleet at a time into an object-storage dataset.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import socket
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

from cananalyze.core import storage

STAGING = "_staging"
SCRATCH = "dask-scratch"  # the local cluster's workers' scratch space: a stage of its own
MANIFEST = "COMMIT.json"
# Hive's partition of no value: DuckDB, pyarrow and Spark read its date as null (unknown)
# and keep the column a date, where a word would make it text
UNKNOWN_DATE = "__HIVE_DEFAULT_PARTITION__"


Dataset = Path | str  # a local folder, or a URL (core/storage)


def root(dataset: str | Path) -> Dataset:
    """The dataset as the layout takes it: a URL stays text, anything else is a Path."""
    return dataset if storage.is_url(dataset) else Path(dataset)


def part_path(dataset: Dataset, table: str, date: str, digest: str):
    if isinstance(dataset, str):
        return f"{dataset.rstrip('/')}/{table}/date={date}/part-{digest}.parquet"
    return dataset / table / f"date={date}" / f"part-{digest}.parquet"


def existing_parts(dataset: Dataset, table: str, digest: str, options: dict | None = None):
    """A log's parts of `table` in any date partition (a rerun may date it differently)."""
    if isinstance(dataset, str):
        return glob_urls(f"{dataset.rstrip('/')}/{table}/date=*/part-{digest}.parquet", options)
    return sorted((dataset / table).glob(f"date=*/part-{digest}.parquet"))


def parts_at(dataset: Dataset, table: str, digest: str, dates) -> list:
    """A log's parts of `table` at these dates (those its `logs` rows name): where its
    earlier parts are, without listing a folder (on object storage a LIST a date folder
    a table, per commit). Local: those there; at a URL: every name (removing an object
    that is not there is no error, and costs what a lookup would)."""
    found = [part_path(dataset, table, d, digest) for d in sorted(set(dates))]
    return found if isinstance(dataset, str) else [p for p in found if p.exists()]


def row_date(value) -> str:
    """A `logs` row's `date` (a date, or None for the unknown one) as its folder names it."""
    if value is None:
        return UNKNOWN_DATE
    return value if isinstance(value, str) else value.isoformat()


# object stores: no folders to make, a prefix is gone with its last object
_FLAT = {"s3", "s3a", "gs", "gcs", "abfs", "abfss", "az", "adl", "oss", "r2"}


def flat(fs) -> bool:
    protocols = fs.protocol if isinstance(fs.protocol, tuple | list) else (fs.protocol,)
    return any(p in _FLAT for p in protocols)


def glob_urls(pattern: str, options: dict | None = None) -> list[str]:
    """The URLs a glob over object storage matches, sorted."""
    fs, path = storage.filesystem(pattern, options)
    fs.invalidate_cache()  # another process may have written since this one listed
    return sorted(storage.url_of(fs, p) for p in fs.glob(path))


def open_part(part: Dataset, options: dict | None = None):
    """A part (path or URL) opened for pyarrow to read."""
    return storage.open_binary(part, options)


def stage(dataset: Dataset, digest: str, options: dict | None = None):
    """A task's stage in this dataset: a locked folder in it, or a remote one's."""
    if isinstance(dataset, str):
        return RemoteStage(dataset, digest, options)
    return Stage(dataset, digest)


def _stage_name(digest: str) -> str:
    return f"{digest[:16]}.{socket.gethostname()}.{os.getpid()}.{uuid.uuid4().hex[:8]}"


class Stage:
    """One task's staging folder, locked while the task lives."""

    def __init__(self, dataset: Path, digest: str) -> None:
        name = _stage_name(digest)
        self.dir = dataset / STAGING / name
        self.dir.mkdir(parents=True)
        self._lock = open(self.dir / ".lock", "w")  # noqa: SIM115 - held for the stage's life
        fcntl.flock(self._lock, fcntl.LOCK_EX)

    def commit(
        self,
        renames: list[tuple[Path, Path]],
        removals: list[Path],
        after: list[tuple[Path, int]] = (),
    ) -> None:
        """Make the removals and renames (src in the stage -> final path), then remove the
        files `after` names (path, inode when read: one replaced since is kept), then drop
        the stage. `after`: a compaction's inputs, gone only once their rows are published."""
        manifest = {
            "renames": [[str(s), str(d)] for s, d in renames],
            "removals": [str(p) for p in removals],
            "after": [[str(p), ino] for p, ino in after],
        }
        # not fsynced: a process that dies (crash, Ctrl-C, kill) leaves the page cache to
        # the next run; after a power cut an unreadable manifest is rolled back, and parts
        # renamed without their logs row are decoded again (no row: not skipped)
        tmp = self.dir / (MANIFEST + ".tmp")
        tmp.write_text(json.dumps(manifest), encoding="utf-8")
        os.replace(tmp, self.dir / MANIFEST)
        _apply(self.dir)
        self.close()

    def close(self) -> None:
        """Drop the stage (after a commit, or to abandon what it holds)."""
        with contextlib.suppress(OSError):
            shutil.rmtree(self.dir)
        self._lock.close()

    def release(self) -> None:
        """Unlock the stage and leave it, as a dead process would: a commit cut short is
        then finished by the next `recover` (its COMMIT.json), also in this process."""
        self._lock.close()


def _apply(stage: Path) -> None:
    """Carry out a stage's COMMIT.json; safe to repeat (a crash during it, then a rerun).
    Raises OSError without one, ValueError or KeyError for one cut short."""
    manifest = json.loads((stage / MANIFEST).read_text(encoding="utf-8"))
    manifest["renames"], manifest["removals"]  # noqa: B018 - both there before any change
    for old in manifest["removals"]:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(old)
    for src, dest in manifest["renames"]:
        if os.path.exists(src):
            os.makedirs(os.path.dirname(dest), exist_ok=True)
            os.replace(src, dest)
    for old, ino in manifest.get("after", ()):
        with contextlib.suppress(FileNotFoundError):
            if os.stat(old).st_ino == ino:  # else a commit replaced it since: a newer part
                os.unlink(old)


def recover(dataset: Dataset, options: dict | None = None) -> tuple[int, int]:
    """Finish or undo what interrupted runs left: (rolled forward, rolled back).

    Stages still locked belong to a live run (another `fleet` into this dataset).
    """
    if isinstance(dataset, str):
        return _recover_remote(dataset, options)
    forward = back = 0
    for stage in _stages(dataset):
        try:
            lock = open(stage / ".lock", "a")  # noqa: SIM115
        except OSError:
            lock = None
        try:
            if lock is not None:
                try:
                    fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    continue  # a live run's
            try:
                _apply(stage)
                forward += 1
            except (OSError, ValueError, KeyError):  # no manifest, or not a whole one
                back += not stage.name.startswith(SCRATCH + ".")  # a scratch space: no log
            shutil.rmtree(stage, ignore_errors=True)
        finally:
            if lock is not None:
                lock.close()
    return forward, back


def _stages(dataset: Path) -> Iterator[Path]:
    root = dataset / STAGING
    if root.is_dir():
        yield from sorted(p for p in root.iterdir() if p.is_dir())


class RemoteStage:
    """One task's stage for a dataset at a URL: a local temporary folder the tables are
    written into, uploaded under `DATASET/_staging/<name>/` when committed.

    Its requests: one PUT an uploaded part and one for COMMIT.json, a server-side copy
    and one bulk delete (the old parts at other dates, then the stage's own objects: no
    LIST, no HEAD); a file:// dataset's stage folder is removed whole."""

    def __init__(self, dataset: str, digest: str, options: dict | None = None) -> None:
        self.dataset, self.options = dataset.rstrip("/"), options
        self.fs, base = storage.filesystem(self.dataset, options)
        self.prefix = f"{base.rstrip('/')}/{STAGING}/{_stage_name(digest)}"
        self.dir = Path(tempfile.mkdtemp(prefix="cananalyze-stage-"))
        self._keys: list[str] = []  # what was (or may have been) uploaded under the prefix

    def commit(
        self, renames: list[tuple[Path, str]], removals: list[str], after: list[str] = ()
    ) -> None:
        """Upload the staged files, write the manifest last, then copy them into place.
        `after`: objects deleted once the copies are made (a compaction's inputs)."""
        try:
            if not flat(self.fs):
                self.fs.makedirs(self.prefix, exist_ok=True)  # a folder where prefixes are
            moves = []
            for i, (src, dest) in enumerate(renames):
                key = f"{self.prefix}/{i}-{src.name}"
                self._keys.append(key)
                self.fs.put_file(str(src), key)
                moves.append([key, _strip(self.fs, dest)])
            manifest = {"renames": moves, "removals": [_strip(self.fs, p) for p in removals]}
            if after:
                manifest["after"] = [_strip(self.fs, p) for p in after]
            self._keys.append(f"{self.prefix}/{MANIFEST}")
            self.fs.pipe_file(f"{self.prefix}/{MANIFEST}", json.dumps(manifest).encode())
            _apply_remote(self.fs, self.prefix)
        finally:
            self.close()

    def close(self) -> None:
        """Drop the local folder and whatever was uploaded under the staging prefix."""
        shutil.rmtree(self.dir, ignore_errors=True)
        with contextlib.suppress(FileNotFoundError, OSError):
            if not flat(self.fs):
                self.fs.rm(self.prefix, recursive=True)
            elif self._keys:  # the manifest last in the list: one bulk delete
                self.fs.rm(self._keys)
        self._keys = []


def _strip(fs, url: str) -> str:
    return fs._strip_protocol(url) if storage.is_url(url) else url


def _apply_remote(fs, prefix: str) -> None:
    """A remote stage's COMMIT.json carried out (safe to repeat): removals (the log's
    parts at other dates), then copies (a source already gone: done by an earlier try)."""
    manifest = json.loads(fs.cat_file(f"{prefix}/{MANIFEST}"))
    manifest["renames"], manifest["removals"]  # noqa: B018 - both there before any change
    if manifest["removals"]:
        with contextlib.suppress(FileNotFoundError):
            if flat(fs):
                fs.rm(list(manifest["removals"]))  # one bulk delete
            else:
                for old in manifest["removals"]:
                    with contextlib.suppress(FileNotFoundError):
                        fs.rm_file(old)
    for src, dest in manifest["renames"]:
        with contextlib.suppress(FileNotFoundError):
            if not flat(fs):
                if not fs.exists(src):
                    continue
                fs.makedirs(fs._parent(dest), exist_ok=True)
            fs.cp_file(src, dest)  # server-side
    _delete_after(fs, list(manifest.get("after", ())))


def _delete_after(fs, after: list[str]) -> None:
    """A compaction's inputs deleted, once its file is in place (one bulk delete)."""
    if not after:
        return
    with contextlib.suppress(FileNotFoundError):
        if flat(fs):
            fs.rm(after)
        else:
            for old in after:
                with contextlib.suppress(FileNotFoundError):
                    fs.rm_file(old)


def _recover_remote(dataset: str, options: dict | None) -> tuple[int, int]:
    fs, base = storage.filesystem(dataset, options)
    where = f"{base.rstrip('/')}/{STAGING}"
    forward = back = 0
    try:
        stages = sorted(fs.ls(where, detail=False))
    except FileNotFoundError:
        return 0, 0
    for prefix in stages:
        try:
            _apply_remote(fs, prefix)
            forward += 1
        except (OSError, ValueError, KeyError):  # no manifest, or not a whole one
            back += 1
        with contextlib.suppress(FileNotFoundError, OSError):
            fs.rm(prefix, recursive=True)
    fs.invalidate_cache()
    return forward, back
