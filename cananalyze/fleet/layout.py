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
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import socket
import uuid
from collections.abc import Iterator
from pathlib import Path

STAGING = "_staging"
SCRATCH = "dask-scratch"  # the local cluster's workers' scratch space: a stage of its own
MANIFEST = "COMMIT.json"


def part_path(dataset: Path, table: str, date: str, digest: str) -> Path:
    return dataset / table / f"date={date}" / f"part-{digest}.parquet"


def existing_parts(dataset: Path, table: str, digest: str) -> list[Path]:
    """A log's parts of `table` in any date partition (a rerun may date it differently)."""
    return sorted((dataset / table).glob(f"date=*/part-{digest}.parquet"))


class Stage:
    """One task's staging folder, locked while the task lives."""

    def __init__(self, dataset: Path, digest: str) -> None:
        name = f"{digest[:16]}.{socket.gethostname()}.{os.getpid()}.{uuid.uuid4().hex[:8]}"
        self.dir = dataset / STAGING / name
        self.dir.mkdir(parents=True)
        self._lock = open(self.dir / ".lock", "w")  # noqa: SIM115 - held for the stage's life
        fcntl.flock(self._lock, fcntl.LOCK_EX)

    def commit(self, renames: list[tuple[Path, Path]], removals: list[Path]) -> None:
        """Make the renames (src in the stage -> final path) and removals, then drop the stage."""
        manifest = {
            "renames": [[str(s), str(d)] for s, d in renames],
            "removals": [str(p) for p in removals],
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


def recover(dataset: Path) -> tuple[int, int]:
    """Finish or undo what interrupted runs left: (rolled forward, rolled back).

    Stages still locked belong to a live run (another `fleet` into this dataset).
    """
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
