"""One declaration per table (outputs/schemas.py): the files, load()'s DataFrames, a fleet's
dataset and the docs all have its columns, read back by pyarrow, DuckDB and pandas."""

from __future__ import annotations

import subprocess
import sys

import duckdb
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, SAMPLES

import cananalyze
from cananalyze.outputs import schemas

LOG = SAMPLES / "faults.log"
RULES = SAMPLES / "rules.yaml"


def _cli(*args: str, rc: int = 0) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, cwd=ROOT
    )
    assert proc.returncode == rc, proc.stderr


def _one_bus(table: schemas.Table) -> list[str]:
    return [n for n in table.names if n != "bus"]


def test_the_docs_list_the_declared_tables():
    page = (ROOT / "docs" / "outputs.md").read_text()
    begin, end = "<!-- schemas:begin -->\n", "<!-- schemas:end -->"
    assert page[page.index(begin) + len(begin) : page.index(end)] == schemas.markdown()


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    out = tmp_path_factory.mktemp("export")
    _cli(
        "export",
        str(LOG),
        "--rules",
        str(RULES),
        "--parquet",
        str(out / "pq"),
        "--csv",
        str(out / "csv"),
        "-q",
    )
    return out


@pytest.mark.parametrize("name", ["frames", "events", "sdo", "findings", "od"])
def test_parquet_files_have_the_declared_columns(export, name):
    """pyarrow reads each file back: the declared columns in their order; where the
    declaration fixes a type (frames, events), that type, and never-null columns REQUIRED."""
    schema = pq.read_schema(export / "pq" / f"{name}.parquet")
    table = schemas.TABLES[name]
    assert schema.names == _one_bus(table)
    for column in table.columns:
        t = column.arrow_type()
        if column.name == "bus" or column.arrow is schemas.DECIDED:
            continue
        field = schema.field(column.name)
        assert field.nullable == column.nullable, column.name
        if t is not None and column.arrow != schemas.CODED:
            assert field.type == t, column.name
        if column.arrow == schemas.CODED:
            assert pa.types.is_dictionary(field.type) and field.type.value_type == pa.string()


def test_csv_signals_and_nodes_have_the_declared_columns(export):
    signals = pcsv.read_csv(export / "csv" / "signals.csv")
    assert signals.column_names == _one_bus(schemas.SIGNALS)
    nodes = pq.read_schema(export / "pq" / "nodes.parquet").names
    assert nodes[-1] == "node"  # the DataFrame's index, as pandas writes it: last
    declared = [n for n in schemas.NODES.names if n in nodes and n != "node"]
    assert nodes[:-1] == declared  # the columns a log has, in the declared order
    assert {"node", "frames", "frames_heartbeat", "last_state", "profile"} <= set(nodes)


def test_load_gives_the_declared_columns():
    cap = cananalyze.load(LOG, rules=RULES)
    for name in ("frames", "signals", "sdo", "events", "findings", "od"):
        assert list(getattr(cap, name).columns) == _one_bus(schemas.TABLES[name]), name


def test_a_fleet_dataset_has_the_declared_columns_and_types(tmp_path):
    """DuckDB reads each table folder: the declared columns, the lineage, the partition."""
    dataset = tmp_path / "ds"
    _cli(
        "fleet",
        str(LOG),
        str(SAMPLES / "demo.log"),
        *("--out", str(dataset), "--workers", "1", "-q"),
        rc=1,  # the samples' faults
    )
    duck = {pa.int16(): "SMALLINT", pa.int32(): "INTEGER", pa.int64(): "BIGINT"}
    duck |= {pa.float64(): "DOUBLE", pa.uint32(): "UINTEGER", pa.uint8(): "UTINYINT"}
    for name, table in schemas.TABLES.items():
        if not table.in_dataset:
            assert not (dataset / name).exists()
            continue
        rows = duckdb.sql(
            f"DESCRIBE SELECT * FROM read_parquet('{dataset}/{name}/*/*.parquet', "
            "hive_partitioning = true)"
        ).fetchall()
        assert [r[0] for r in rows] == [*table.names, "source", "hash", "version", "date"], name
        types = {r[0]: r[1] for r in rows}
        for column in table.columns:
            want = duck.get(column.fleet_type)
            if want:
                assert types[column.name] == want, (name, column.name)
