"""Parquet and CSV export of the Capture tables: one file per table in a directory.

Tables: frames, signals, sdo, events, findings, nodes. Parquet keeps the column
types (categoricals, nullable node-IDs); CSV is for spreadsheets. Each file is
written atomically, so a cut-off export never leaves a truncated table.
"""

from __future__ import annotations

from pathlib import Path

from ...capture import Capture
from ...errors import UsageError
from ..atomic import atomic_path

TABLES = ("frames", "signals", "sdo", "events", "findings", "nodes")


def _tables(cap: Capture):
    for name in TABLES:
        yield name, _plain_columns(getattr(cap, name))


def _plain_columns(df):
    """Object columns holding mixed types (SDO `value`, findings `measured`/`expected`:
    numbers, strings, lists) as text, None kept: Parquet needs one type per column."""
    mixed = {}
    for col in df.columns:
        if df[col].dtype == object:
            types = {type(v) for v in df[col] if not _missing(v)}
            if len(types) > 1 or (types and not types <= {str}):
                mixed[col] = df[col].map(lambda v: None if _missing(v) else str(v))
    return df.assign(**mixed) if mixed else df


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and v != v)


def _outdir(path: str | Path) -> Path:
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise UsageError(f"{d}: exists and is not a directory")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"{d}: cannot create the output directory ({exc.strerror})") from None
    return d


def write_parquet(cap: Capture, path: str | Path, compression: str = "snappy") -> dict[str, int]:
    """<dir>/<table>.parquet for every table; returns rows per table."""
    d = _outdir(path)
    rows = {}
    for name, df in _tables(cap):
        with atomic_path(d / f"{name}.parquet") as tmp:
            df.to_parquet(tmp, engine="pyarrow", index=name == "nodes", compression=compression)
        rows[name] = len(df)
    return rows


def write_csv(cap: Capture, path: str | Path) -> dict[str, int]:
    """<dir>/<table>.csv for every table; returns rows per table.

    Written by pyarrow's C++ CSV writer: pandas' to_csv takes ~15 s on a
    million-frame log, Arrow about one.
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv

    d = _outdir(path)
    rows = {}
    for name, df in _tables(cap):
        if name == "nodes":
            df = df.reset_index()
        table = pa.Table.from_pandas(df, preserve_index=False)
        cols = []
        for col in table.columns:
            if pa.types.is_dictionary(col.type):
                col = col.cast(pa.string())
            elif pa.types.is_null(col.type):
                col = col.cast(pa.string())
            cols.append(col)
        table = pa.table(cols, names=table.column_names)
        with atomic_path(d / f"{name}.csv") as tmp:
            pacsv.write_csv(table, tmp)
        rows[name] = len(df)
    return rows
