"""`fleet compact`: a dataset's small parts rewritten into files near a target size, for
the query engines that pay per file (a log's seven parts are kilobytes each).

Per table and date partition, the parts under the target size (a log's
`part-<hash>.parquet`, or an earlier compaction's `part-compact-<id>.parquet` not yet
full) are read together, sorted by time (then by log) and written as one file of row
groups in time order. Every row keeps its lineage columns (`source`, `hash`,
`version`); the file's footer also lists the hashes it holds (`cananalyze.hashes`), so
finding a log's rows reads footers, not the files.

Publishing goes through a stage like a fleet task's (layout.Stage): the new file is
renamed into place, then its inputs are removed (each only if it is still the file
that was read: a part a fleet run replaced meanwhile stays). A reader listing between
the two sees those logs twice, told apart by nothing but the file; a crash between them
is finished by the next `fleet` or `compact` (the stage's COMMIT.json).

A rerun decides from rows, not file names: the driver reads the `logs` rows of every
file; a worker looks a hash up in the loose `logs` part, else in the compacted files
whose footer lists it. When a fleet run commits a log whose rows are also in a
compacted file (`--force`, a changed configuration, a changed file at the same path),
`reconcile` rewrites that file without them, in place (one rename: readers see the old
file or the new one): a loose part is always newer than a compacted copy of the same
hash, and a loose `logs` row for a path retires that path's other hashes.

Compaction and the reconcile hold one lock (`flock` on the `_staging` folder), so they
never interleave; a fleet run's tasks do not take it. Each publish also waits for the
`cananalyze query` runs reading the dataset (`reading`: `flock` on its folder, shared).
A dataset at a URL: see the section at the end (a remote stage's copy, then a bulk
delete; `visible` is how a reader sees each row once meanwhile).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import uuid
from collections.abc import Iterator
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import pyarrow as pa

from cananalyze.core.defaults import COMPACT_TARGET_SIZE
from cananalyze.fleet import layout, schema

COMPACTED = "part-compact-"  # a compacted file's name: part-compact-<id>.parquet
HASHES = b"cananalyze.hashes"  # footer key: the JSON list of the log hashes in the file


@dataclass
class CompactResult:
    """What a compaction did: the part files before and after, their sizes (bytes)."""

    sizes_before: list[int]
    sizes_after: list[int]
    merged: int = 0  # files written by merging
    reconciled: int = 0  # compacted files rewritten without rows a later commit replaced


def is_compacted(path: Path) -> bool:
    return path.name.startswith(COMPACTED)


def order(table: str) -> list[tuple[str, str]]:
    """A table's sort keys in a compacted file: its time, then the log (ties stay apart)."""
    names = [c for c, _ in schema.COLUMNS[table]]
    time = next((c for c in ("t", "t_first") if c in names), None)
    keys = ([time] if time else []) + ["hash"] + (["node"] if "node" in names and not time else [])
    return [(k, "ascending") for k in keys]


def _parts(dataset: Path, table: str, compacted: bool | None = None) -> list[Path]:
    """A table's part files: all, only the compacted ones, or only a log's own."""
    prefix = COMPACTED if compacted else "part-"  # the compacted: a glob of their own
    found = sorted((dataset / table).glob(f"date=*/{prefix}*.parquet"))
    return [p for p in found if compacted is None or is_compacted(p) == compacted]


def _digest(part: Path) -> str:
    return part.name[len("part-") : -len(".parquet")]


@lru_cache(maxsize=4096)
def _footer_hashes(path: str, ino: int, mtime_ns: int) -> frozenset[str]:
    import pyarrow.parquet as pq

    meta = pq.read_schema(path).metadata or {}
    return frozenset(json.loads(meta.get(HASHES, b"[]")))


def hashes_of(part: Path) -> frozenset[str]:
    """The log hashes a compacted file holds, from its footer (each version read once)."""
    st = part.stat()
    return _footer_hashes(str(part), st.st_ino, st.st_mtime_ns)


def compacted_row(dataset: Path, digest: str) -> dict | None:
    """The `logs` row of this content in a compacted file, or None."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    for part in _parts(dataset, "logs", compacted=True):
        with contextlib.suppress(OSError, ValueError):
            if digest in hashes_of(part):
                found = pq.read_table(part)
                rows = found.filter(pc.equal(found["hash"].cast(pa.string()), digest))
                if rows.num_rows:
                    return rows.to_pylist()[0]
    return None


@contextlib.contextmanager
def _flock(folder: Path, how: int) -> Iterator[None]:
    """`flock` on a folder itself: no lock file is left in the dataset."""
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, how)
        yield
    finally:
        os.close(fd)


def locked(dataset: Path):
    """The dataset's compaction lock (on its `_staging` folder), held: waits for a
    compaction or reconcile running."""
    (dataset / layout.STAGING).mkdir(parents=True, exist_ok=True)
    return _flock(dataset / layout.STAGING, fcntl.LOCK_EX)


@contextlib.contextmanager
def reading(dataset: Path) -> Iterator[None]:
    """Held by `cananalyze query` while it lists and reads the parts (a shared lock on the
    dataset's folder): a compaction's publish (its file in, its inputs out) takes it
    alone, so the query sees each row once and no part goes from under it. Read-only
    datasets too: nothing is written."""
    try:
        fd = os.open(dataset, os.O_RDONLY)
    except OSError:  # a folder that cannot be opened: read without it
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH)
        yield
    finally:
        os.close(fd)


def _read(parts: list[Path], table: str) -> pa.Table:
    """Parts of one table as one table of the dataset's schema (a part written before a
    column was added reads it as null), each label column one dictionary."""
    import pyarrow.dataset as pads

    found = pads.dataset([str(p) for p in parts], format="parquet", schema=schema.schema(table))
    return found.to_table().combine_chunks().unify_dictionaries()


def _write(data: pa.Table, table: str, dest: Path, compression: str) -> None:
    """Rows in time order, in row groups of the export's size; the hashes in the footer."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from cananalyze.outputs.tables.writer import ROW_GROUP

    keys = order(table)
    plain = {  # labels by their text (Arrow sorts no dictionary column)
        k: data[k].cast(data[k].type.value_type)
        if pa.types.is_dictionary(data[k].type)
        else data[k]
        for k, _ in keys
    }
    data = data.take(pc.sort_indices(pa.table(plain), sort_keys=keys))
    hashes = sorted(pc.unique(data["hash"].cast(pa.string())).to_pylist())
    meta = {**(data.schema.metadata or {}), HASHES: json.dumps(hashes).encode()}
    pq.write_table(
        data.replace_schema_metadata(meta), dest, row_group_size=ROW_GROUP, compression=compression
    )


def _publish(
    dataset: Path, staged_from, dest: Path, after: list[tuple[Path, int]], removals=()
) -> None:
    stage = layout.Stage(dataset, "compact")
    staged = stage.dir / "part.parquet"
    try:
        staged_from(staged)
    except BaseException:
        stage.close()
        raise
    with _flock(dataset, fcntl.LOCK_EX):  # no `query` reading meanwhile (`reading`)
        try:
            stage.commit([(staged, dest)] if staged.exists() else [], list(removals), after)
        except BaseException:
            stage.release()  # cut short: its COMMIT.json is finished by the next recover
            raise


def _merge(dataset: Path, table: str, parts: list[Path], compression: str) -> None:
    """`parts` (one partition's) into one new compacted file, then removed."""
    after = [(p, p.stat().st_ino) for p in parts]  # before reading: a later swap is seen
    data = _read(parts, table)
    dest = parts[0].parent / f"{COMPACTED}{uuid.uuid4().hex[:16]}.parquet"
    _publish(dataset, lambda staged: _write(data, table, staged, compression), dest, after)


def _stale(data: pa.Table, fresh: set[str], old: dict[str, set[str]]):
    """The rows of `data` that a batch's commits replaced: those of a hash it wrote again
    (`fresh`), and those of a path's earlier content (`old`: {path: its earlier hashes})."""
    import pyarrow.compute as pc

    hashes = data["hash"].cast(pa.string())
    mask = pc.is_in(hashes, pa.array(sorted(fresh), pa.string()))
    pairs = sorted(f"{path}\0{h}" for path, hs in old.items() for h in hs)
    if pairs:
        keys = pc.binary_join_element_wise(data["source"].cast(pa.string()), hashes, "\0")
        mask = pc.or_(mask, pc.is_in(keys, pa.array(pairs, pa.string())))
    return mask


def retire(
    dataset: Path, fresh: set[str], old: dict[str, set[str]], compression: str = "snappy"
) -> int:
    """Before a batch's parts are merged: the earlier copies of its logs' rows dropped from
    the compacted files (a hash decoded again, a changed path's old content). Once merged,
    the new rows are in a compacted file too, and nothing would tell the two copies apart
    (the reconcile's rules are about loose parts). Files rewritten; `locked` held."""
    import pyarrow.compute as pc

    candidates = set(fresh).union(*old.values())
    rewritten = 0
    for table in schema.TABLES:
        for part in _parts(dataset, table, compacted=True):
            if not hashes_of(part) & candidates:
                continue
            ino = part.stat().st_ino
            data = _read([part], table)
            keep = data.filter(pc.invert(_stale(data, fresh, old)))
            if keep.num_rows == data.num_rows:
                continue
            _rewrite(dataset, part, ino, keep, table, compression)
            rewritten += 1
    return rewritten


def merge_logs(
    dataset: Path,
    digests: set[str],
    compression: str = "snappy",
    old: dict[str, set[str]] | None = None,
) -> int:
    """The parts of these logs (a fleet batch's, just committed one by one) merged, per
    table and date, into shared files: several logs a file from the start. How many
    files were written. Under the compaction lock, as any merge; first the earlier
    copies of those logs' rows leave the compacted files (`retire`)."""
    written = 0
    with locked(dataset):
        retire(dataset, digests, old or {}, compression)
        for table in schema.TABLES:
            by_partition: dict[Path, list[Path]] = {}
            for digest in sorted(digests):
                for part in layout.existing_parts(dataset, table, digest):
                    by_partition.setdefault(part.parent, []).append(part)
            for parts in by_partition.values():
                if len(parts) > 1:
                    _merge(dataset, table, parts, compression)
                    written += 1
    return written


def _bins(parts: list[Path], target: int) -> Iterator[list[Path]]:
    """Consecutive groups of parts whose sizes add up to about `target` (a part over it:
    alone), largest first so full files come out full."""
    return _sized_bins([(p.stat().st_size, p) for p in parts], target)


def _logged(dataset: Path) -> set[str]:
    """Every hash a `logs` row names: loose parts' names, compacted files' footers."""
    found = {_digest(p) for p in _parts(dataset, "logs", compacted=False)}
    return found.union(*(hashes_of(p) for p in _parts(dataset, "logs", compacted=True)))


def reconcile(dataset: Path, compression: str = "snappy") -> int:
    """Compacted files rewritten without the rows a later commit replaced; how many.

    Call with `locked` held. Stale in a compacted file of a table: a hash that also has
    a loose part in that table (decoded again: `--force`, a changed configuration, a
    rerun dated otherwise); in every table, a hash whose loose `logs` row failed (a
    failed redo writes its `logs` part only: its old rows go, as a fleet commit removes
    a log's old parts), a hash whose path has a loose `logs` row of another hash (the
    file changed), and a hash with no `logs` row at all. Not a hash with only a loose
    `logs` part: a compaction merges a table's parts by size, so a log's `logs` part may
    stay loose beside its merged rows."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    # first a compaction cut short between its new file and its inputs' removal is
    # finished: else its inputs, loose parts, would make its new file's rows stale
    layout.recover(dataset)
    compacted = {t: _parts(dataset, t, compacted=True) for t in schema.TABLES}
    if not any(compacted.values()):
        return 0
    loose = {t: {_digest(p) for p in _parts(dataset, t, compacted=False)} for t in schema.TABLES}
    retired: set[str] = set()
    if loose["logs"]:
        newer: dict[str, set[str]] = {}
        rows = _read(_parts(dataset, "logs", compacted=False), "logs")
        for row in rows.select(["source", "hash", "status"]).to_pylist():
            newer.setdefault(row["source"], set()).add(row["hash"])
            if row["status"] != "ok":
                retired.add(row["hash"])
        for part in compacted["logs"]:
            for row in pq.read_table(part, columns=["source", "hash"]).to_pylist():
                if row["source"] in newer and row["hash"] not in newer[row["source"]]:
                    retired.add(row["hash"])
    # and rows of no log: a changed file's old rows a compaction read as the run that
    # replaced them removed their parts (no logs row left to retire them by)
    logged = _logged(dataset)
    rewritten = 0
    for table, parts in compacted.items():
        for part in parts:
            held = hashes_of(part)
            drop = held & (loose[table] | retired) | (held - logged)
            if not drop:
                continue
            ino = part.stat().st_ino
            data = _read([part], table)
            keep = data.filter(pc.invert(pc.is_in(data["hash"].cast(pa.string()), pa.array(drop))))
            _rewrite(dataset, part, ino, keep, table, compression)
            rewritten += 1
    return rewritten


def _rewrite(dataset: Path, part: Path, ino: int, keep, table: str, compression: str) -> None:
    """`part` (inode `ino` when it was read) replaced by the rows of it that stay, or
    removed when none stay, by the same commit protocol as the rest of the dataset."""
    if keep.num_rows:
        _publish(dataset, lambda s: _write(keep, table, s, compression), part, [])
    else:
        _publish(dataset, lambda s: None, part, [(part, ino)])


def compact(
    dataset: str | Path,
    target_size: int = COMPACT_TARGET_SIZE,
    compression: str = "snappy",
    dates: set[str] | None = None,
    options: dict | None = None,
) -> CompactResult:
    """Every table's partitions compacted (see the module's docstring), or only those of
    `dates` (`fleet --compact`: the days a run wrote); UsageError for a folder that is no
    fleet dataset. A dataset at a URL (`options`: fsspec's) is compacted through its
    store (see below)."""
    from cananalyze.core.errors import UsageError

    if isinstance(layout.root(dataset), str):
        if target_size <= 0:
            raise UsageError(f"--target-size must be positive (got {target_size})")
        return _remote_compact(str(dataset), target_size, compression, dates, options)
    dataset = Path(dataset)
    if not (dataset / "logs").is_dir():
        raise UsageError(f"{dataset}: not a fleet dataset (no logs table in it)")
    if target_size <= 0:
        raise UsageError(f"--target-size must be positive (got {target_size})")
    with locked(dataset):
        layout.recover(dataset)  # before the sizes: a stage finished is no file of ours
        out = CompactResult(_sizes(dataset), [])
        out.reconciled = reconcile(dataset, compression)
        logged = _logged(dataset)
        for table in schema.TABLES:
            for partition in sorted((dataset / table).glob("date=*")):
                if dates is not None and partition.name.removeprefix("date=") not in dates:
                    continue
                small = [
                    p
                    for p in partition.glob("part-*.parquet")
                    if p.stat().st_size < target_size
                    # a log's part without its logs row: a commit under way, left to it
                    and (is_compacted(p) or table == "logs" or _digest(p) in logged)
                ]
                for group in _bins(small, target_size):
                    if len(group) > 1:
                        _merge(dataset, table, group, compression)
                        out.merged += 1
        out.sizes_after = _sizes(dataset)
    return out


def _sizes(dataset: Path) -> list[int]:
    return [p.stat().st_size for t in schema.TABLES for p in _parts(dataset, t)]


def median(sizes: list[int]) -> float:
    s = sorted(sizes)
    if not s:
        return 0.0
    mid = len(s) // 2
    return float(s[mid]) if len(s) % 2 else (s[mid - 1] + s[mid]) / 2


# --- a dataset at a URL (object storage) ---------------------------------------------
#
# The same rules as above, with the store's operations: one listing of the dataset (a
# LIST a 1,000 objects, not one a folder), the inputs read through fsspec, the new file
# published by a remote stage (layout.RemoteStage: uploaded under `_staging/`,
# COMMIT.json, a server-side copy into place, then the inputs deleted in one bulk
# delete, then the stage). A copy over an object's name replaces it whole (a reconcile's
# rewrite in place). No lock: as for fleet runs, one writer at a time into an
# object-storage dataset (a fleet run or a compaction); readers see each row once
# through `cananalyze query` (`visible_parts`), see the module docstring of query.py.


class _Remote:
    """A dataset at a URL: its fsspec file system and its parts, listed once a pass."""

    def __init__(self, dataset: str, options: dict | None = None) -> None:
        from cananalyze.core import storage

        self.url, self.options = dataset.rstrip("/"), options
        self.fs, base = storage.filesystem(self.url, options)
        self.base = base.rstrip("/")
        self._hashes: dict[tuple[str, str], frozenset[str]] = {}

    def parts(self) -> dict[str, int]:
        """{key: size} of every part of every table (`_staging` left out): one find."""
        return visible(self.fs, self.base)[0]

    def table(self, key: str) -> str:
        return key[len(self.base) + 1 :].split("/", 1)[0]

    def url_of(self, key: str) -> str:
        return self.url + key[len(self.base) :]

    def read(
        self, keys: list[str], table: str, columns: list[str] | None = None, chunk: int = 256
    ) -> pa.Table:
        """Parts as one table of the dataset's schema (`_read`'s): each file fetched whole,
        a chunk of them at a time by concurrent GETs (one request a file)."""
        import pyarrow.parquet as pq

        want = schema.schema(table)
        if columns is not None:
            want = pa.schema([want.field(c) for c in columns])
        tables = []
        for i in range(0, len(keys), chunk):
            blobs = self.fs.cat(keys[i : i + chunk])  # a file gone: FileNotFoundError
            for key in keys[i : i + chunk]:
                found = pq.read_table(pa.BufferReader(blobs[key]))
                have = set(found.column_names)
                tables.append(
                    pa.table(
                        [
                            _typed(found[f.name], f.type)
                            if f.name in have
                            else pa.nulls(found.num_rows, f.type)
                            for f in want
                        ],
                        schema=want,
                    )
                )
        if not tables:
            return want.empty_table()
        return pa.concat_tables(tables).combine_chunks().unify_dictionaries()

    def hashes_of(self, key: str) -> frozenset[str]:
        """A compacted file's hashes, from its footer (one ranged read)."""
        import pyarrow.parquet as pq

        tag = (key, str(self.fs.info(key).get("ETag", "")))
        if tag not in self._hashes:
            with self.fs.open(key, "rb") as f:
                meta = pq.read_schema(f).metadata or {}
            self._hashes[tag] = frozenset(json.loads(meta.get(HASHES, b"[]")))
        return self._hashes[tag]

    def publish(self, staged_from, dest: str | None, after: list[str] = ()) -> None:
        """The file `staged_from` writes copied to `dest` (None: no file), then `after`
        deleted, through a remote stage (a crash: finished or undone by `recover`)."""
        stage = layout.RemoteStage(self.url, "compact", self.options)
        staged = stage.dir / "part.parquet"
        try:
            staged_from(staged)
        except BaseException:
            stage.close()
            raise
        renames = [(staged, self.url_of(dest))] if dest is not None and staged.exists() else []
        stage.commit(renames, [], [self.url_of(k) for k in after])


def _typed(column, typ):
    """A column as the dataset's schema types it (a part written before a type changed)."""
    return column if column.type == typ else column.cast(typ)


def visible(fs, base: str) -> tuple[dict[str, int], set[str]]:
    """({key: size} of a dataset's parts, the keys a compaction under way has replaced):
    one listing of the dataset, `_staging` included, then each compaction's COMMIT.json
    there. A stage whose new file is in the listing has published it: its inputs still
    listed are about to go, and are left out (a reader that kept them would see their
    rows twice); one whose file is not there yet leaves its inputs in."""
    fs.invalidate_cache()
    try:
        found = fs.find(base, detail=True)
    except FileNotFoundError:
        return {}, set()
    parts: dict[str, int] = {}
    manifests = []
    for key, info in found.items():
        rel = key[len(base) + 1 :].split("/")
        if rel[0] == layout.STAGING and rel[-1] == layout.MANIFEST:
            manifests.append(key)
        elif (
            len(rel) == 3
            and rel[0] in schema.TABLES
            and rel[1].startswith("date=")
            and rel[2].startswith("part-")
            and rel[2].endswith(".parquet")
        ):
            parts[key] = int(info.get("size") or 0)
    gone: set[str] = set()
    for key in manifests:
        with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
            manifest = json.loads(fs.cat_file(key))
            if manifest.get("after") and all(d in parts for _, d in manifest["renames"]):
                gone.update(manifest["after"])
    for key in gone:
        parts.pop(key, None)
    return parts, gone


def _name(key: str) -> str:
    return key.rsplit("/", 1)[1]


def _key_digest(key: str) -> str:
    return _name(key)[len("part-") : -len(".parquet")]


def _remote_merge(r: _Remote, table: str, keys: list[str], compression: str) -> None:
    data = r.read(keys, table)
    dest = f"{keys[0].rsplit('/', 1)[0]}/{COMPACTED}{uuid.uuid4().hex[:16]}.parquet"
    r.publish(lambda staged: _write(data, table, staged, compression), dest, keys)


def reconcile_remote(dataset: str, compression: str = "snappy", options: dict | None = None) -> int:
    """`reconcile` of a dataset at a URL (a fleet run's end)."""
    return _remote_reconcile(_Remote(dataset, options), compression)


def _remote_retire(
    r: _Remote, fresh: set[str], old: dict[str, set[str]], compression: str, dates
) -> int:
    import pyarrow.compute as pc

    if dates is None:
        keys = [k for k in r.parts() if _name(k).startswith(COMPACTED)]
    else:
        keys = []
        for table in schema.TABLES:
            for date in sorted(dates):
                with contextlib.suppress(FileNotFoundError):
                    folder = f"{r.base}/{table}/date={date}"
                    keys += [
                        k for k in r.fs.ls(folder, detail=False) if _name(k).startswith(COMPACTED)
                    ]
    candidates = set(fresh).union(*old.values())
    rewritten = 0
    for key in sorted(keys):
        if not r.hashes_of(key) & candidates:
            continue
        table = r.table(key)
        data = r.read([key], table)
        keep = data.filter(pc.invert(_stale(data, fresh, old)))
        if keep.num_rows == data.num_rows:
            continue
        if keep.num_rows:
            r.publish(lambda s, k=keep, t=table: _write(k, t, s, compression), key)
        else:
            r.publish(lambda s: None, None, [key])
        rewritten += 1
    return rewritten


def _remote_reconcile(r: _Remote, compression: str = "snappy") -> int:
    """`reconcile` for a dataset at a URL: the same rows dropped, the same way."""
    import pyarrow.compute as pc

    layout.recover(r.url, r.options)
    parts = r.parts()
    compacted = {t: [] for t in schema.TABLES}
    loose = {t: {} for t in schema.TABLES}
    for key in parts:
        table = r.table(key)
        if _name(key).startswith(COMPACTED):
            compacted[table].append(key)
        else:
            loose[table][_key_digest(key)] = key
    if not any(compacted.values()):
        return 0
    retired: set[str] = set()
    if loose["logs"]:
        newer: dict[str, set[str]] = {}
        rows = r.read(sorted(loose["logs"].values()), "logs", ["source", "hash", "status"])
        for row in rows.to_pylist():
            newer.setdefault(row["source"], set()).add(row["hash"])
            if row["status"] != "ok":
                retired.add(row["hash"])
        if compacted["logs"]:
            for row in r.read(compacted["logs"], "logs", ["source", "hash"]).to_pylist():
                if row["source"] in newer and row["hash"] not in newer[row["source"]]:
                    retired.add(row["hash"])
    logged = set(loose["logs"]).union(*(r.hashes_of(k) for k in compacted["logs"]))
    rewritten = 0
    for table, keys in compacted.items():
        for key in keys:
            held = r.hashes_of(key)
            drop = held & (set(loose[table]) | retired) | (held - logged)
            if not drop:
                continue
            data = r.read([key], table)
            keep = data.filter(pc.invert(pc.is_in(data["hash"].cast(pa.string()), pa.array(drop))))
            if keep.num_rows:
                r.publish(lambda s, k=keep, t=table: _write(k, t, s, compression), key)
            else:
                r.publish(lambda s: None, None, [key])
            rewritten += 1
    return rewritten


def _remote_compact(
    dataset: str, target_size: int, compression: str, dates: set[str] | None, options
) -> CompactResult:
    from cananalyze.core.errors import UsageError

    r = _Remote(dataset, options)
    layout.recover(r.url, options)  # before the sizes: a stage finished is no file of ours
    parts = r.parts()
    if not any(r.table(k) == "logs" for k in parts):
        raise UsageError(f"{dataset}: not a fleet dataset (no logs table in it)")
    out = CompactResult(list(parts.values()), [])
    out.reconciled = _remote_reconcile(r, compression)
    if out.reconciled:
        parts = r.parts()
    logged = {_key_digest(k) for k in parts if r.table(k) == "logs"}
    logged = logged.union(
        *(r.hashes_of(k) for k in parts if r.table(k) == "logs" and _name(k).startswith(COMPACTED))
    )
    by_partition: dict[tuple[str, str], list[tuple[int, str]]] = {}
    for key, size in parts.items():
        table, folder = r.table(key), key.rsplit("/", 1)[0]
        if dates is not None and folder.rsplit("/date=", 1)[1] not in dates:
            continue
        small = size < target_size and (
            _name(key).startswith(COMPACTED) or table == "logs" or _key_digest(key) in logged
        )
        if small:
            by_partition.setdefault((table, folder), []).append((size, key))
    for (table, _), sized in sorted(by_partition.items()):
        for group in _sized_bins(sized, target_size):
            if len(group) > 1:
                _remote_merge(r, table, group, compression)
                out.merged += 1
    out.sizes_after = list(r.parts().values())
    return out


def _sized_bins(sized: list[tuple[int, Any]], target: int) -> Iterator[list]:
    """The keys of (size, key) pairs in consecutive groups whose sizes add up to about
    `target` (one over it: alone), largest first; keys (paths, object names) break ties."""
    current: list = []
    total = 0
    for size, key in sorted(sized, key=lambda sp: (-sp[0], sp[1])):
        if current and total + size > target:
            yield current
            current, total = [], 0
        current.append(key)
        total += size
    if current:
        yield current


def merge_remote_logs(
    dataset: str,
    logs: dict[str, tuple[str, bool]],
    compression: str,
    options: dict | None,
    old: dict[str, set[str]] | None = None,
    earlier: set[str] | None = None,
) -> int:
    """`merge_logs` at a URL: {digest: (date, decoded ok)} of a batch's logs just committed;
    their parts named from their dates (every table's for a log decoded, the `logs` part
    alone for a failed one: no listing), merged per table and date. Files written. First
    `retire` in the compacted files of the `earlier` dates (where the tasks' earlier
    rows can be: their `known`; None: every date), each date folder listed once."""
    r = _Remote(dataset, options)
    if earlier is None or earlier:
        _remote_retire(r, set(logs), old or {}, compression, earlier)
    written = 0
    for table in schema.TABLES:
        by_date: dict[str, list[str]] = {}
        for digest, (date, ok) in sorted(logs.items()):
            if ok or table == "logs":
                by_date.setdefault(date, []).append(layout.part_path(r.base, table, date, digest))
        for keys in by_date.values():
            if len(keys) > 1:
                _remote_merge(r, table, keys, compression)
                written += 1
    return written
