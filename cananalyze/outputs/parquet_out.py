"""Parquet and CSV export of the Capture tables: one file per table in a directory.

Tables: frames, signals, sdo, events, findings, nodes. Parquet keeps the column
types (categoricals, nullable node-IDs); CSV is for spreadsheets. Each file is
written atomically, so a cut-off export never leaves a truncated table.
"""

from __future__ import annotations

from pathlib import Path

from ..capture import Capture
from ..errors import UsageError
from .atomic import atomic_path

TABLES = ("frames", "signals", "sdo", "events", "findings", "nodes")


def _tables(cap: Capture):
    for name in TABLES:
        df = getattr(cap, name)
        if name == "sdo" and "value" in df:
            df = df.assign(value=df["value"].map(lambda v: None if v is None else str(v)))
        yield name, df


def _outdir(path: str | Path) -> Path:
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise UsageError(f"{d}: exists and is not a directory")
    d.mkdir(parents=True, exist_ok=True)
    return d


def write_parquet(cap: Capture, path: str | Path) -> dict[str, int]:
    """<dir>/<table>.parquet for every table; returns rows per table."""
    d = _outdir(path)
    rows = {}
    for name, df in _tables(cap):
        with atomic_path(d / f"{name}.parquet") as tmp:
            df.to_parquet(tmp, engine="pyarrow", index=name == "nodes")
        rows[name] = len(df)
    return rows


def write_csv(cap: Capture, path: str | Path) -> dict[str, int]:
    """<dir>/<table>.csv for every table; returns rows per table."""
    d = _outdir(path)
    rows = {}
    for name, df in _tables(cap):
        with atomic_path(d / f"{name}.csv") as tmp:
            df.to_csv(tmp, index=name == "nodes", float_format="%.9g" if name != "frames" else None)
        rows[name] = len(df)
    return rows
