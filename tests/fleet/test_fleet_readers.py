"""Datasets that query engines like (issue 39 item 4): the `date` partition typed as a
date for every reader, and `fleet compact` rewriting small parts into large time-ordered
files without losing, duplicating or orphaning a log's rows. Checked with pyarrow and
DuckDB directly, not through cananalyze's readers."""

from __future__ import annotations

import shutil
from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.dataset as ds
import pytest

from cananalyze.fleet import query, schema
from cananalyze.fleet.orchestrate import run_fleet

SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def _undated(src: Path, dest: Path) -> None:
    """A candump log with times from the logger's start (no date: Hive's null partition)."""
    lines = src.read_text().splitlines()
    t0 = float(lines[0].split(")")[0][1:])
    out = [f"({float(ln.split(')')[0][1:]) - t0:.6f}){ln.split(')', 1)[1]}" for ln in lines]
    dest.write_text("\n".join(out) + "\n")


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> list[str]:
    folder = tmp_path_factory.mktemp("logs")
    for p in sorted(SAMPLES.glob("*.log")) + sorted(SAMPLES.glob("*.asc")):
        shutil.copy(p, folder / p.name)
    _undated(SAMPLES / "demo.log", folder / "undated.log")
    return sorted(str(p) for p in folder.iterdir())


@pytest.fixture(scope="module")
def dataset(logs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ds") / "ds"
    result = run_fleet(logs, out, workers=1)
    assert not result.failed
    return out


def test_pyarrow_reads_the_date_partition_as_a_date(dataset):
    found = ds.dataset(dataset / "frames", format="parquet", partitioning=schema.partitioning())
    assert found.schema.field("date").type == pa.date32()
    dates = set(found.to_table(columns=["date"]).column("date").to_pylist())
    assert None in dates and len(dates) == 2  # the samples' day, and the undated log's null
    assert schema.dataset_schema("frames").field("date").type == pa.date32()


@pytest.mark.parametrize("only_undated", [False, True])
def test_duckdb_in_query_reads_the_date_partition_as_a_date(dataset, logs, tmp_path, only_undated):
    if only_undated:  # DuckDB alone would guess text for a `date=__HIVE_DEFAULT_PARTITION__`
        dataset = tmp_path / "undated"
        assert not run_fleet(
            [p for p in logs if p.endswith("undated.log")], dataset, workers=1
        ).failed
        glob = str(dataset / "logs" / "date=*" / "*.parquet")
        guessed = duckdb.sql(
            f"SELECT typeof(date) FROM read_parquet('{glob}', hive_partitioning = true)"
        ).fetchall()
        assert guessed == [("VARCHAR",)]
    con = query.connect(dataset)
    for table in schema.TABLES:
        types = {r[0]: r[1] for r in con.execute(f"DESCRIBE {table}").fetchall()}
        assert types["date"] == "DATE", table
