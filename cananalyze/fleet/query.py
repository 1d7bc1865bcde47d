"""DuckDB over a fleet dataset: each table a view of its hive-partitioned Parquet parts.

A local dataset is read under `compact.reading` (a shared lock: no compaction publishes
meanwhile). One at a URL has no lock: the view names the files one listing found
(`compact.visible`: the inputs of a compaction whose new file is already in place left
out, so no row is read twice), and a query that meets a file deleted since (that
compaction finished) lists again and runs again, a few times at most.
"""

from __future__ import annotations

import contextlib
import re
from pathlib import Path

from cananalyze.core import storage
from cananalyze.core.errors import UsageError
from cananalyze.core.extras import need
from cananalyze.fleet.compact import reading
from cananalyze.fleet.schema import TABLES, duckdb_hive_types


def _sql_text(value: str) -> str:
    return "'" + value.replace("'", "''") + "'"


def connect(dataset: str | Path, storage_options: dict | None = None):
    """An in-memory DuckDB connection with a view per table the dataset holds.

    `hive_partitioning` turns the `date=YYYY-MM-DD` folders into a column `date`, typed
    as the dataset declares it (`hive_types`: a DATE, also when every folder is the
    partition of no value);
    `union_by_name` lets a dataset written by an older cananalyze (columns added since)
    still be read whole. A dataset at a URL is read through its fsspec file system,
    registered into DuckDB (no httpfs extension to download). MissingExtra without the
    fleet extra.
    """
    duckdb = need("duckdb", "query", "fleet")
    con = duckdb.connect()
    if storage.is_url(dataset):
        fs, base = storage.filesystem(str(dataset), storage_options)
        fs.invalidate_cache()
        root = str(dataset).rstrip("/")
        if not fs.isdir(base):
            raise UsageError(f"{root}: no such dataset")
        con.register_filesystem(fs)
        from cananalyze.fleet.compact import visible

        base = base.rstrip("/")
        listed = sorted(visible(fs, base)[0])

        def parts(table: str) -> list[str] | None:
            mine = [root + k[len(base) :] for k in listed if k.startswith(f"{base}/{table}/")]
            return mine or None
    else:
        root = Path(dataset)
        if not root.is_dir():
            raise UsageError(f"{root}: no such dataset folder")

        def parts(table: str) -> str | None:
            if not any((root / table).glob("date=*/part-*.parquet")):
                return None
            return str(root / table / "date=*" / "part-*.parquet")

    made = []
    for table in TABLES:
        found = parts(table)
        if found is None:
            continue
        pattern = (
            _sql_text(found)
            if isinstance(found, str)
            else "[" + ", ".join(_sql_text(f) for f in found) + "]"
        )
        con.execute(
            f"CREATE VIEW {table} AS SELECT * FROM read_parquet({pattern}, "
            f"hive_partitioning = true, hive_types = {duckdb_hive_types()}, "
            "union_by_name = true)"
        )
        made.append(table)
    if not made:
        raise UsageError(f"{root}: not a fleet dataset (no {'/'.join(TABLES)} parts in it)")
    return con


def query(
    dataset: str | Path, sql: str, storage_options: dict | None = None
) -> tuple[list[str], list[tuple]]:
    """(column names, rows) of `sql` over the dataset's views; UsageError for bad SQL."""
    duckdb = need("duckdb", "query", "fleet")
    local = not storage.is_url(dataset) and Path(dataset).is_dir()
    for attempt in range(_TRIES):
        with reading(Path(dataset)) if local else contextlib.nullcontext():  # no compaction
            con = connect(dataset, storage_options)  # publishes while the parts are read
            try:
                rel = con.execute(sql)
                names = [d[0] for d in rel.description or []]
                return names, rel.fetchall()
            except duckdb.Error as exc:
                text = str(exc).strip()
                if not local and attempt + 1 < _TRIES and _GONE.search(text):
                    continue  # a file listed, deleted since (a compaction): list again
                first = text.splitlines()[0] if text else type(exc).__name__
                raise UsageError(f"query: {first}") from None
            finally:
                con.close()
    raise AssertionError("unreachable")


_TRIES = 5
_GONE = re.compile(r"FileNotFound|No such file|NoSuchKey|Not Found|404", re.IGNORECASE)
