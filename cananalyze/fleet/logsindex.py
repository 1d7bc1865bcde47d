"""The dataset's `logs` rows as a rerun reads them: each `logs` part file read once, its
rows kept in `DATASET/_index/logs.parquet`, a cache the next run checks against a listing.

A rerun decides which logs to skip from every `logs` row (fleet/orchestrate). Read from
the parts themselves that is one file a log until a compaction (10,000 one-row parts:
~5 s of pyarrow's CPU locally, one GET each on object storage). The index holds the rows
of every part it saw with the part's identity as the listing gives it (locally inode,
size and modification time; on object storage size, ETag and time): a run lists the
`logs` table (one `scandir` a date folder, or the store's LIST pages), takes the rows of
the parts whose identity is unchanged from the index, reads only the other parts (new,
rewritten: their rows replace the old ones), drops those of parts gone, and writes the
index again (atomically: a rename, or one PUT) only when it changed. The parts stay the
only truth: an index that is missing, unreadable or of another format is ignored (every
part read, as before), and a part's rows are never taken from it unless the part is
listed as it was when they were read. Readers of the dataset do not see it (`_index`,
like `_staging`, is skipped by Spark, pyarrow and the dataset's globs).
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import pyarrow as pa

from cananalyze.core import storage
from cananalyze.fleet import layout, schema

INDEX = "_index"
NAME = "logs.parquet"
FORMAT = b"1"  # the index's own layout; another is ignored (read every part instead)
_KEY = b"cananalyze.logs-index"
TAG = "__part"  # the part's name and identity, one text: `date=.../part-...parquet|id`

# what a recorded row tells a rerun: its skip key, and the verdict a skipped log reports
ROW_COLUMNS = (
    *("source", "hash", "version", "config", "size", "mtime_ns", "run"),
    *("status", "error", "frames", "findings", "violations", "skipped_lines", "format"),
)


def _plain() -> pa.Schema:
    """The `logs` parts' schema, labels as plain text (one buffer for 10,000 parts' rows,
    where dictionaries would be one each to unify)."""
    logs = schema.schema("logs")
    return pa.schema(
        [
            pa.field(f.name, f.type.value_type if pa.types.is_dictionary(f.type) else f.type)
            for f in logs
        ]
    )


def _want() -> pa.Schema:
    logs = _plain()
    return pa.schema(
        [logs.field(c) for c in ROW_COLUMNS] + [pa.field("date", pa.string()), (TAG, pa.string())]
    )


def logs_rows(dataset: layout.Dataset, options: dict | None = None) -> list[dict] | None:
    """Every `logs` row of the dataset (ROW_COLUMNS, and `date` as its folder names it),
    [] when there are none, None when a part cannot be read (the caller then decides
    nothing from them). Reads the index and the parts it does not hold; updates it."""
    if isinstance(dataset, Path):
        listed = _listed_local(dataset)
        store = None
    else:
        fs, base = storage.filesystem(dataset, options)
        fs.invalidate_cache()
        base = base.rstrip("/")
        store = (fs, base)
        listed = _listed_remote(fs, base)
    if listed is None:
        return None
    if not listed:
        return []
    index = _read_index(dataset, store)
    have = set(index[TAG].to_pylist()) if index is not None else set()
    tags = {f"{rel}|{ident}": rel for rel, ident in listed.items()}
    fresh_tags = {t: rel for t, rel in tags.items() if t not in have}
    try:
        fresh = _read_parts(dataset, store, fresh_tags) if fresh_tags else None
    except (OSError, ValueError):  # a local part gone since the listing too: hashed
        return None
    kept = index
    if index is not None and not have <= tags.keys():  # parts gone: their rows go
        import pyarrow.compute as pc

        # (only then: pa.array of Python values makes pyarrow import pandas, ~0.5 s)
        kept = index.filter(pc.is_in(index[TAG], value_set=pa.array(list(tags), pa.string())))
    parts = [t for t in (kept, fresh) if t is not None and t.num_rows]
    if not parts:
        return []  # (no empty_table(): pyarrow imports pandas for it, ~0.5 s)
    table = pa.concat_tables(parts).combine_chunks() if len(parts) > 1 else parts[0]
    if fresh_tags or (index is None) or kept.num_rows != index.num_rows:
        with contextlib.suppress(OSError, ValueError):  # a read-only dataset: read again next time
            _write_index(dataset, store, table)
    return table.drop_columns([TAG]).to_pylist()


def _listed_local(dataset: Path) -> dict[str, str] | None:
    """{`date=.../part-....parquet`: "inode:size:mtime_ns"} of the local `logs` table."""
    out: dict[str, str] = {}
    try:
        folders = list(os.scandir(dataset / "logs"))
    except FileNotFoundError:
        return {}
    except OSError:
        return None
    try:
        for d in folders:
            if not d.name.startswith("date=") or not d.is_dir():
                continue
            for f in os.scandir(d.path):
                if f.name.startswith("part-") and f.name.endswith(".parquet"):
                    st = f.stat()
                    out[f"{d.name}/{f.name}"] = f"{st.st_ino}:{st.st_size}:{st.st_mtime_ns}"
    except FileNotFoundError:
        pass  # a date folder a compaction removed meanwhile: its parts are elsewhere now
    except OSError:
        return None
    return out


def _listed_remote(fs, base: str) -> dict[str, str] | None:
    """{`date=.../part-....parquet`: "size:ETag:time"} of the `logs` table at a URL: the
    listing's own fields (its LIST pages, no request a file)."""
    where = f"{base}/logs/"
    try:
        found = fs.find(where, detail=True)
    except FileNotFoundError:
        return {}
    except OSError:
        return None
    out = {}
    for key, info in found.items():
        rel = key[len(where) :]
        name = rel.rsplit("/", 1)[-1]
        if rel.startswith("date=") and name.startswith("part-") and name.endswith(".parquet"):
            tag = info.get("ETag") or info.get("etag") or info.get("md5Hash") or info.get("ino")
            when = storage.listed_mtime_ns(info)
            out[rel] = f"{info.get('size')}:{str(tag or '').strip(chr(34))}:{when}"
    return out


def _index_path(dataset: layout.Dataset, store) -> str:
    if store is None:
        return str(Path(dataset) / INDEX / NAME)
    return f"{store[1]}/{INDEX}/{NAME}"


def _read_index(dataset: layout.Dataset, store) -> pa.Table | None:
    """The index, or None when it is missing, unreadable or of another layout."""
    import pyarrow.parquet as pq

    try:
        # ParquetFile, not read_table: no pyarrow.dataset to import for one file
        if store is None:
            table = pq.ParquetFile(_index_path(dataset, store)).read()
        else:
            blob = store[0].cat_file(_index_path(dataset, store))
            table = pq.ParquetFile(pa.BufferReader(blob)).read()
    except (OSError, ValueError):
        return None
    if (table.schema.metadata or {}).get(_KEY) != FORMAT:
        return None
    try:
        return table.select(_want().names).cast(_want())
    except (KeyError, ValueError, pa.ArrowInvalid):
        return None


def _write_index(dataset: layout.Dataset, store, table: pa.Table) -> None:
    import pyarrow.parquet as pq

    table = table.replace_schema_metadata({_KEY: FORMAT})
    if store is None:
        from cananalyze.core.atomic import atomic_path

        dest = Path(_index_path(dataset, store))
        dest.parent.mkdir(exist_ok=True)
        with atomic_path(dest) as tmp:
            pq.write_table(table, tmp)
        return
    fs, dest = store[0], _index_path(dataset, store)
    if not layout.flat(fs):
        fs.makedirs(dest.rsplit("/", 1)[0], exist_ok=True)  # file://: a folder to make
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    fs.pipe_file(dest, sink.getvalue().to_pybytes())  # one PUT: whole or not at all


def _read_parts(dataset: layout.Dataset, store, tags: dict[str, str]) -> pa.Table | None:
    """The rows of these parts ({tag: rel}), each with its tag and date (None: no rows);
    OSError or ValueError when one cannot be read. An object deleted since the listing
    (a compaction's input) is passed over: its logs are hashed by their workers, never
    wrongly skipped."""
    want = _want()
    logs = _plain()
    by_rel = {rel: t for t, rel in tags.items()}
    tables = []

    def add(rel: str, found: pa.Table) -> None:
        have = set(found.column_names)
        n = found.num_rows
        cols = [
            _as(found[c], logs.field(c).type) if c in have else pa.nulls(n, logs.field(c).type)
            for c in ROW_COLUMNS
        ]
        date = rel.split("/", 1)[0][len("date=") :]
        cols += [pa.array([date] * n, pa.string()), pa.array([by_rel[rel]] * n, pa.string())]
        tables.append(pa.Table.from_arrays(cols, schema=want))

    if store is None:
        import pyarrow.dataset as pads

        root = Path(dataset) / "logs"
        paths = [str(root / rel) for rel in by_rel]
        found = pads.dataset(paths, schema=logs, format="parquet")
        scan = found.scanner(columns=list(ROW_COLUMNS))
        batches, rels = [], []
        for tagged in scan.scan_batches():  # one threaded scan, each batch's file told
            batches.append(tagged.record_batch)
            rel = os.path.relpath(tagged.fragment.path, root)
            rels += [rel] * tagged.record_batch.num_rows
        if rels:
            found = pa.Table.from_batches(batches)
            dates = [rel.split("/", 1)[0][len("date=") :] for rel in rels]
            found = found.append_column(want.field("date"), pa.array(dates, pa.string()))
            tag = pa.array([by_rel[rel] for rel in rels], pa.string())
            tables.append(found.append_column(want.field(TAG), tag))
    else:
        import pyarrow.parquet as pq

        fs, base = store
        keys = {f"{base}/logs/{rel}": rel for rel in by_rel}
        names = sorted(keys)
        for i in range(0, len(names), 1000):  # concurrent GETs, a chunk at a time
            blobs = fs.cat(names[i : i + 1000], on_error="omit")
            for key, blob in blobs.items():
                if isinstance(blob, bytes | bytearray):
                    add(keys[key], pq.read_table(pa.BufferReader(blob)))
    if not tables:
        return None
    return pa.concat_tables(tables).combine_chunks()


def _as(column, typ):
    """A column as the dataset's schema types it (a part written before a type changed)."""
    return column if column.type == typ else column.cast(typ)
