"""Spark reads the fleet dataset as DuckDB does: per table, the same rows (in total and
per `date` partition, the unknown date included), the same columns and the same types.

Spark runs in local mode (`local[1]`, driver bound to 127.0.0.1, no UI) on a Java runtime
from Debian's packages (`.ci/run` installs it); without pyspark or Java this skips, saying
which. The dataset is made by `cananalyze fleet` from the samples and, when the real data
is here, real logs of four formats and three kinds of date (from the log, from the file's
name, unknown)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import duckdb
import pytest
from conftest import REAL, SAMPLES

from cananalyze.cli.main import main
from cananalyze.fleet.schema import TABLES

pytestmark = [
    pytest.mark.slow,  # a JVM starts, and a Dask cluster
    pytest.mark.filterwarnings("ignore:PySpark does not yet fully support pandas"),
]

REAL_LOGS = [
    "hilch__canopen-message-interpreter/pcan1.trc",  # PEAK trace, dated by its frames
    "jclinton830__canopen_test/candump.txt",  # no times, no date in its name: unknown
    "hardbyte__python-can/test_CanMessage.blf",
    "isPointless__Sevcon/can_180209_154604.txt",  # dated by its name
]
JAVA_MIN = 17  # pyspark 4 runs on Java 17 or 21


def _java_major() -> int | None:
    """The major version of the `java` on PATH, None when there is none."""
    java = shutil.which("java")
    if java is None:
        return None
    out = subprocess.run([java, "-version"], capture_output=True, text=True, timeout=60)
    found = re.search(r'version "(\d+)(?:\.(\d+))?', out.stderr + out.stdout)
    if not found:
        return 0
    major = int(found.group(1))
    return int(found.group(2) or 0) if major == 1 else major  # "1.8.0" is Java 8


# one vocabulary for both engines' names of a type
DUCKDB_KINDS = {
    **dict.fromkeys(
        "TINYINT SMALLINT INTEGER BIGINT HUGEINT UTINYINT USMALLINT UINTEGER UBIGINT".split(), "int"
    ),
    **dict.fromkeys(["FLOAT", "DOUBLE"], "float"),
    "VARCHAR": "string",
    "BOOLEAN": "bool",
    "DATE": "date",
    "BLOB": "binary",
}
SPARK_KINDS = {
    **dict.fromkeys(["tinyint", "smallint", "int", "bigint"], "int"),
    **dict.fromkeys(["float", "double"], "float"),
    "string": "string",
    "boolean": "bool",
    "date": "date",
    "binary": "binary",
}


def duckdb_kind(name: str) -> str:
    if name.endswith("[]"):
        return "list"
    if name.startswith(("DECIMAL", "NUMERIC")):
        return "float"
    if name.startswith("TIMESTAMP"):
        return "timestamp"
    return DUCKDB_KINDS.get(name, f"other:{name}")


def spark_kind(name: str) -> str:
    if name.startswith("array<"):
        return "list"
    if name.startswith("decimal"):
        return "float"
    if name.startswith("timestamp"):
        return "timestamp"
    return SPARK_KINDS.get(name, f"other:{name}")


@pytest.fixture(scope="module")
def spark(tmp_path_factory):
    """One local Spark session for the module, on 127.0.0.1 only, stopped at the end."""
    pytest.importorskip("pyspark", reason="pyspark is not installed (the dev extra has it)")
    major = _java_major()
    if major is None:
        pytest.skip("no Java runtime (java is not on PATH; .ci/run installs default-jre-headless)")
    if major < JAVA_MIN:
        pytest.skip(f"Java {major} is too old for pyspark 4 (needs {JAVA_MIN} or newer)")
    from pyspark.sql import SparkSession

    scratch = tmp_path_factory.mktemp("spark")
    # the JVM's own address too: without it Spark looks up the machine's interfaces and
    # names a non-loopback one ("using 192.0.2.2 instead"); tests talk on 127.0.0.1 only
    local_ip = os.environ.get("SPARK_LOCAL_IP")
    os.environ["SPARK_LOCAL_IP"] = "127.0.0.1"
    session = (
        SparkSession.builder.master("local[1]")
        .appName("cananalyze-fleet-test")
        .config("spark.driver.host", "127.0.0.1")
        .config("spark.driver.bindAddress", "127.0.0.1")
        .config("spark.ui.enabled", "false")
        .config("spark.ui.showConsoleProgress", "false")
        .config("spark.local.dir", str(scratch / "local"))
        .config("spark.sql.warehouse.dir", str(scratch / "warehouse"))
        .getOrCreate()
    )
    session.sparkContext.setLogLevel("ERROR")
    try:
        yield session
    finally:
        from pyspark import SparkContext

        gateway = SparkContext._gateway
        session.stop()
        if gateway is not None:  # the JVM too: it would outlive the module in this process
            gateway.shutdown()
            gateway.proc.kill()
            gateway.proc.wait()
            SparkContext._gateway = SparkContext._jvm = None
        if local_ip is None:
            os.environ.pop("SPARK_LOCAL_IP", None)
        else:
            os.environ["SPARK_LOCAL_IP"] = local_ip


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """`cananalyze fleet` over the samples (their folder's network.toml gives signals) and
    the real logs that are here."""
    inputs = sorted(str(p) for p in SAMPLES.glob("*.log"))
    inputs += [str(REAL / r) for r in REAL_LOGS if (REAL / r).exists()]
    out = tmp_path_factory.mktemp("fleet") / "ds"
    rc = main(["fleet", *inputs, "--out", str(out), "--workers", "1", "-q"])
    assert rc in (0, 1)  # the samples break rules on purpose: 1
    return out


def _duckdb(table_dir: Path):
    con = duckdb.connect()
    src = f"read_parquet('{table_dir}/date=*/part-*.parquet', hive_partitioning = true)"
    columns = [(r[0], r[1]) for r in con.execute(f"DESCRIBE SELECT * FROM {src}").fetchall()]
    by_date = dict(con.execute(f"SELECT date, count(*) FROM {src} GROUP BY date").fetchall())
    return columns, by_date


def test_the_dataset_holds_every_table_and_every_log(dataset):
    assert sorted(p.name for p in dataset.iterdir() if not p.name.startswith("_")) == sorted(TABLES)
    con = duckdb.connect()
    logs = f"read_parquet('{dataset}/logs/date=*/part-*.parquet', hive_partitioning = true)"
    rows = con.execute(f"SELECT status, count(*) FROM {logs} GROUP BY status").fetchall()
    expected = len(list(SAMPLES.glob("*.log"))) + sum((REAL / r).exists() for r in REAL_LOGS)
    assert dict(rows) == {"ok": expected}
    if (REAL / REAL_LOGS[1]).exists():  # the unknown date: Hive's null partition
        assert con.execute(f"SELECT count(*) FROM {logs} WHERE date IS NULL").fetchone() == (1,)


@pytest.mark.parametrize("table", TABLES)
def test_spark_reads_each_table_as_duckdb_does(spark, dataset, table):
    columns, by_date = _duckdb(dataset / table)
    frame = spark.read.parquet(str(dataset / table))  # Spark finds `date=` itself
    spark_columns = [(f.name, f.dataType.simpleString()) for f in frame.schema.fields]

    assert [n for n, _ in spark_columns] == [n for n, _ in columns]
    assert columns[-1] == ("date", "DATE")  # the partition, read as a date by both
    kinds = {n: duckdb_kind(t) for n, t in columns}
    assert not [k for k in kinds.values() if k.startswith("other:")], columns
    assert {n: spark_kind(t) for n, t in spark_columns} == kinds

    spark_by_date = {r["date"]: r["count"] for r in frame.groupBy("date").count().collect()}
    assert spark_by_date == by_date
    assert frame.count() == sum(by_date.values())
    if table in ("frames", "logs", "nodes", "events"):
        assert frame.count() > 0  # every log has these rows: a real comparison, not 0 == 0
