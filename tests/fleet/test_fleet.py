"""`cananalyze fleet` and `query`: real logs and broken files on a real local Dask cluster
(127.0.0.1 only), read back with pyarrow.dataset, DuckDB and junitparser."""

from __future__ import annotations

import hashlib
import json
import shutil
import threading
from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest
from conftest import real_file
from exported import wide_signals_as_long

from cananalyze import __version__
from cananalyze.cli.main import main
from cananalyze.fleet import layout
from cananalyze.fleet.orchestrate import run_fleet
from cananalyze.fleet.schema import LINEAGE, TABLES
from cananalyze.fleet.schema import schema as fleet_schema
from cananalyze.fleet.task import UNKNOWN_DATE, LogTask, process
from cananalyze.outputs.tables.stream import TableSink
from cananalyze.pipeline import Options, build_decoder, open_source, run

REAL_LOGS = [
    "hilch__canopen-message-interpreter/pcan1.trc",  # PEAK trace, 2023-02-07
    "hilch__canopen-message-interpreter/ixxat1.trc",
    "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log",  # candump -l
    "jclinton830__canopen_test/candump.txt",  # no timestamps: dated by the file
    "hardbyte__python-can/test_CanMessage.blf",
    "hardbyte__python-can/test_CanMessage.asc.gz",
    "isPointless__Sevcon/can_180209_154604.txt",
]
NET_LOG = "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log"
# the I/O module sends TPDO1 every 100 ms: declared as 20 ms, every one is late
NETWORK = "[nodes.127.tpdo.1]\ncob_id = 0x1FF\nevent_timer = 20\n"


def _sha(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """One fleet run over real logs, a folder with its own network.toml, and broken files."""
    root = tmp_path_factory.mktemp("fleet")
    logs = [real_file(r) for r in REAL_LOGS]
    folder = root / "bench_rig"
    folder.mkdir()
    (folder / "network.toml").write_text(NETWORK)
    (folder / "rig.log").symlink_to(real_file(NET_LOG))
    broken = root / "broken"
    broken.mkdir()
    (broken / "garbage.blf").write_bytes(bytes(range(256))[::-1] * 8)  # binary, not a log
    # a BLF file signature and nothing readable after it: a failure, not "0 frames"
    (broken / "headonly.blf").write_bytes(b"LOGG" + bytes(range(256)) * 4)
    (broken / "notes.txt").write_text("these are not CAN frames\njust words\n")
    blf = real_file("hardbyte__python-can/issue_1905.blf").read_bytes()
    (broken / "truncated.blf").write_bytes(blf[: len(blf) // 2])
    (broken / "empty.log").write_bytes(b"")
    inputs = [str(p) for p in logs] + [str(folder), str(broken / "*")]
    dataset = root / "ds"
    junit = root / "fleet.xml"
    result = run_fleet(inputs, dataset, Options(checks=True), workers=2, junit=str(junit))
    return {
        "root": root,
        "dataset": dataset,
        "result": result,
        "logs": logs,
        "rig": folder / "rig.log",
        "broken": broken,
        "junit": junit,
    }


# the date partition as a date, as docs/fleet.md tells pyarrow users (Hive's partition of
# no value, an undated log's, reads as null)
DATES = ds.partitioning(pa.schema([("date", pa.date32())]), flavor="hive")


def _table(dataset: Path, name: str) -> pa.Table:
    return ds.dataset(dataset / name, format="parquet", partitioning=DATES).to_table()


@pytest.mark.slow
def test_cluster_is_local_only(fleet):
    r = fleet["result"]
    assert r.scheduler.startswith("tcp://127.0.0.1:")
    assert len(r.workers) == 2 and all(w.startswith("tcp://127.0.0.1:") for w in r.workers)
    assert r.dashboard is None or r.dashboard.startswith("http://127.0.0.1:")


def test_every_input_has_one_logs_row_and_failures_are_isolated(fleet):
    logs = _table(fleet["dataset"], "logs").to_pylist()
    by_source = {r["source"]: r for r in logs}
    broken = fleet["broken"]
    expected = {str(p) for p in fleet["logs"]} | {str(fleet["rig"])}
    names = ("garbage.blf", "headonly.blf", "notes.txt", "truncated.blf", "empty.log")
    expected |= {str(broken / n) for n in names}
    assert set(by_source) == expected
    assert len(logs) == len(expected)
    for p in fleet["logs"]:
        row = by_source[str(p)]
        assert row["status"] == "ok", row
        assert row["hash"] == _sha(p) and row["version"] == __version__
        assert row["frames"] > 0 and row["seconds"] > 0
    for name in ("garbage.blf", "headonly.blf", "notes.txt", "empty.log"):
        row = by_source[str(broken / name)]
        assert row["status"] == "failed"
        assert row["error"].startswith(str(broken / name)) and "\n" not in row["error"]
        assert row["frames"] == 0
    # what a truncated BLF held before the cut is kept, the rest counted as skipped
    cut = by_source[str(broken / "truncated.blf")]
    assert cut["status"] == "ok" and cut["frames"] > 0 and cut["skipped_lines"] > 0
    assert "no frame could be read" in by_source[str(broken / "headonly.blf")]["error"]
    # a failed log has a logs row and no data parts; the rest of the fleet completed
    failed = {r["hash"] for r in logs if r["status"] == "failed"}
    frames = _table(fleet["dataset"], "frames")
    assert failed.isdisjoint(set(frames.column("hash").to_pylist()))
    assert fleet["result"].exit_code == 1
    assert {r["source"] for r in fleet["result"].failed} == {
        r["source"] for r in logs if r["status"] == "failed"
    }


def test_date_partition_is_the_logs_own_time(fleet):
    logs = {r["source"]: r for r in _table(fleet["dataset"], "logs").to_pylist()}
    pcan1 = logs[str(real_file(REAL_LOGS[0]))]
    assert str(pcan1["date"]) == "2023-02-07" and pcan1["date_from"] == "log"
    brake = logs[str(real_file(REAL_LOGS[2]))]
    assert str(brake["date"]) == "2025-08-07"
    undated = logs[str(real_file(REAL_LOGS[3]))]  # candump without timestamps, no date in
    assert undated["date_from"] == "unknown"  # its name: never the copy's mtime (issue 44)
    assert undated["date"] is None  # Hive's partition of no value: a null date
    assert layout.part_path(fleet["dataset"], "frames", UNKNOWN_DATE, undated["hash"]).is_file()
    part = layout.part_path(fleet["dataset"], "frames", "2023-02-07", pcan1["hash"])
    assert part.is_file()


def _single_export(path: Path, out: Path, opts: Options) -> Path:
    source = open_source(path, opts)
    run(source, build_decoder(opts), [TableSink(out, "parquet")], opts)
    return out


def _signal_key(r: dict) -> tuple:
    return (r["t"], r["node"], r["pdo"], r["cob_id"], r["signal"])


def _long_rows(path: Path) -> list[dict]:
    """The wide signals file's rows one per value (DuckDB's UNPIVOT), in a fixed order."""
    long = wide_signals_as_long(path)
    long = long.astype({"node": int, "cob_id": int, "pdo": str, "signal": str, "unit": str})
    rows = pa.Table.from_pandas(long, preserve_index=False).to_pylist()  # Python values
    return sorted(rows, key=_signal_key)


def test_fleet_frames_equal_the_single_log_exports(fleet, tmp_path):
    """Every row of every table: the fleet's part is the one-log export plus lineage."""
    frames = _table(fleet["dataset"], "frames")
    total = 0
    for i, log in enumerate(fleet["logs"]):
        single = _single_export(log, tmp_path / str(i), Options(checks=True))
        digest = _sha(log)
        for name in ("frames", "signals", "events", "findings"):
            mine = pq.read_table(single / f"{name}.parquet").to_pylist()
            part = [
                p
                for p in (fleet["dataset"] / name).glob(f"date=*/part-{digest}.parquet")
                if p.is_file()
            ]
            assert len(part) == 1, (name, log)
            theirs = pq.read_table(part[0]).to_pylist()
            if name == "signals":  # the export's is wide, the dataset's one row per value
                mine = _long_rows(single / "signals.parquet")
                theirs = sorted(theirs, key=_signal_key)
            assert len(theirs) == len(mine), (name, log)
            for row in theirs:
                assert row.pop("source") == str(log) and row.pop("hash") == digest
                assert row.pop("version") == __version__
            # the dataset's columns: the export's, lineage, and `bus` (null: one bus)
            norm = (
                [
                    {k: r.get(k) if k == "bus" else r[k] for k in theirs[0] if k in r or k == "bus"}
                    for r in mine
                ]
                if theirs
                else []
            )
            assert json.dumps(theirs, default=str) == json.dumps(norm, default=str), (name, log)
        total += pq.ParquetFile(single / "frames.parquet").metadata.num_rows
    ok = {str(p) for p in fleet["logs"]}
    in_fleet = sum(1 for s in frames.column("source").to_pylist() if s in ok)
    assert in_fleet == total > 20_000


def test_duckdb_reads_the_dataset_with_hive_partitioning(fleet):
    dataset = fleet["dataset"]
    con = duckdb.connect()
    for name in TABLES:
        glob = str(dataset / name / "*" / "*.parquet")
        n, dates = con.execute(
            f"SELECT count(*), count(DISTINCT date) FROM read_parquet('{glob}', "
            "hive_partitioning = true)"
        ).fetchone()
        assert n == _table(dataset, name).num_rows, name
        assert dates >= 2 or name in ("sdo",), name
    typ = con.execute(
        f"SELECT typeof(date) FROM read_parquet('{dataset}/logs/*/*.parquet', "
        "hive_partitioning = true) LIMIT 1"
    ).fetchone()[0]
    assert typ == "DATE"
    # frames.data: the payload's bytes (a BLOB to DuckDB), dlc of them
    bad = con.execute(
        f"SELECT typeof(data), count(*) FROM read_parquet('{dataset}/frames/*/*.parquet') "
        "WHERE octet_length(data) <> dlc AND flags & 2 = 0 GROUP BY ALL"
    ).fetchall()
    assert bad == []
    ((blob,),) = con.execute(
        f"SELECT DISTINCT typeof(data) FROM read_parquet('{dataset}/frames/*/*.parquet')"
    ).fetchall()
    assert blob == "BLOB"
    # one schema per table in every part (Spark and pyarrow.dataset need it), no null
    # type, and the lineage columns last
    for name in TABLES:
        parts = list((dataset / name).glob("date=*/*.parquet"))
        schemas = {str(pq.read_schema(p).remove_metadata()) for p in parts}
        assert len(parts) >= 5 and len(schemas) == 1, name
        schema = pq.read_schema(parts[0])
        assert schema.equals(fleet_schema(name)), name
        assert not any(pa.types.is_null(f.type) for f in schema), name
        assert [f.name for f in schema][-3:] == [c for c, _ in LINEAGE]


def test_findings_are_checks_findings_and_the_folder_network_file_applies(fleet, tmp_path):
    """A log's findings in the fleet are `check`'s for it; the rig folder's network.toml
    (TPDO1 event timer 20 ms) gives the findings `check --network` gives."""
    from cananalyze.outputs.findings import FindingsSink

    def check(path, **kw):
        opts = Options(checks=True, **kw)
        sink = FindingsSink(quiet=True)
        run(open_source(path, opts), build_decoder(opts), [sink], opts)
        return sorted((f.rule, f.node, round(f.t, 6)) for f in sink.findings)

    findings = _table(fleet["dataset"], "findings").to_pylist()

    def fleet_findings(source):
        return sorted(
            (f["rule"], f["node"], round(f["t"], 6)) for f in findings if f["source"] == source
        )

    pcan1 = real_file(REAL_LOGS[0])
    assert fleet_findings(str(pcan1)) == check(pcan1) != []
    rig = fleet["rig"]
    net = tmp_path / "net.toml"
    net.write_text(NETWORK)
    with_network = check(rig, network=net)
    assert fleet_findings(str(rig)) == with_network
    assert with_network != check(rig)  # the network file made a difference
    assert any(r == "pdo_async" and n == 127 for r, n, _ in with_network)


def test_junit_has_one_testsuite_per_log(fleet):
    from junitparser import JUnitXml

    xml = JUnitXml.fromfile(str(fleet["junit"]))
    suites = {s.name: s for s in xml}
    assert len(suites) == len(fleet["result"].results)
    garbage = suites[str(fleet["broken"] / "garbage.blf")]
    assert garbage.errors == 1
    pcan1 = suites[str(real_file(REAL_LOGS[0]))]
    assert pcan1.failures >= 1 and pcan1.tests > 1


@pytest.mark.slow
def test_second_run_skips_and_force_redoes(fleet, tmp_path):
    dataset = tmp_path / "ds"
    logs = [str(real_file(r)) for r in REAL_LOGS[:2]]
    first = run_fleet(logs, dataset, workers=1)
    assert not first.skipped and first.exit_code == 1  # pcan1 has violations
    parts = sorted(dataset.glob("*/date=*/*.parquet"))
    stamps = [p.stat().st_mtime_ns for p in parts]
    again = run_fleet(logs, dataset, workers=1)
    assert len(again.skipped) == 2 and again.frames == 0
    assert again.exit_code == 1  # the recorded violations still count
    assert [p.stat().st_mtime_ns for p in sorted(dataset.glob("*/date=*/*.parquet"))] == stamps
    forced = run_fleet(logs, dataset, workers=1, force=True)
    assert not forced.skipped and forced.frames == first.frames
    assert sorted(dataset.glob("*/date=*/*.parquet")) == parts  # replaced, not doubled
    assert _table(dataset, "logs").num_rows == 2
    assert not any((dataset / layout.STAGING).iterdir())


@pytest.mark.slow
def test_a_rerun_with_another_configuration_decodes_again(tmp_path):
    """The skip key holds the options and the content of the files they name: tables
    made under one network file are not kept when the next run gives another."""
    import pyarrow.dataset as ds

    from cananalyze.pipeline import Options

    log = str(real_file(REAL_LOGS[0]))
    net = tmp_path / "network.toml"
    net.write_text("[nodes.40]\ndevice = 'cia402'\n")
    dataset = tmp_path / "ds"
    first = run_fleet([log], dataset, Options(network=net), workers=1)
    assert not first.skipped
    same = run_fleet([log], dataset, Options(network=net), workers=1)
    assert len(same.skipped) == 1  # same bytes, same configuration: nothing to do
    net.write_text("[nodes.40]\ndevice = 'cia401'\n")  # same path, other content
    other = run_fleet([log], dataset, Options(network=net), workers=1)
    assert not other.skipped and other.frames == first.frames
    profiles = ds.dataset(dataset / "nodes", partitioning="hive").to_table().to_pylist()
    assert {r["profile"] for r in profiles if r["node"] == 40} == {"cia401"}
    logs = ds.dataset(dataset / "logs", partitioning="hive").to_table().to_pylist()
    assert len(logs) == 1 and len(logs[0]["config"]) == 64


def test_failed_logs_are_tried_again_and_an_existing_scheduler_is_used(tmp_path):
    from distributed import LocalCluster

    dataset = tmp_path / "ds"
    bad = tmp_path / "late.log"
    bad.write_text("not yet a log\n")
    ok = str(real_file(REAL_LOGS[2]))
    with LocalCluster(
        n_workers=1, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        first = run_fleet([ok, str(bad)], dataset, scheduler=cluster.scheduler_address)
        assert first.scheduler == cluster.scheduler_address
        status = {r["source"]: r["status"] for r in first.results}
        assert status == {ok: "ok", str(bad): "failed"}
        # the file is complete now (a logger still writing it when the fleet first ran)
        shutil.copy(real_file(REAL_LOGS[3]), bad)
        again = run_fleet([ok, str(bad)], dataset, scheduler=cluster.scheduler_address)
    assert {r["source"]: r["skipped"] for r in again.results} == {ok: True, str(bad): False}
    logs = {r["source"]: r for r in _table(dataset, "logs").to_pylist()}
    assert len(logs) == 2 and logs[str(bad)]["status"] == "ok"  # the failed row replaced


def test_interrupted_commits_are_finished_or_undone(tmp_path):
    dataset = tmp_path / "ds"
    # a stage cut off before its manifest: rolled back
    cut = layout.Stage(dataset, "a" * 64)
    (cut.dir / "frames.parquet").write_bytes(b"half")
    cut._lock.close()  # its process died: the lock is gone
    # a stage cut off after its manifest, one rename done: rolled forward
    done = layout.Stage(dataset, "b" * 64)
    srcs = []
    for name in ("frames", "logs"):
        src = done.dir / f"{name}.parquet"
        pq.write_table(pa.table({"x": [1]}), src)
        srcs.append((src, layout.part_path(dataset, name, "2024-01-02", "b" * 64)))
    manifest = {"renames": [[str(s), str(d)] for s, d in srcs], "removals": []}
    (done.dir / layout.MANIFEST).write_text(json.dumps(manifest))
    srcs[0][1].parent.mkdir(parents=True)
    srcs[0][0].replace(srcs[0][1])
    done._lock.close()
    # a manifest cut short (a power cut before the page cache reached the disk): rolled back
    torn = layout.Stage(dataset, "d" * 64)
    (torn.dir / layout.MANIFEST).write_text('{"renames": [["')
    torn._lock.close()
    # a stage whose run is alive: left alone
    live = layout.Stage(dataset, "c" * 64)
    assert layout.recover(dataset) == (1, 2)
    assert not torn.dir.exists()
    assert all(d.is_file() for _, d in srcs)
    assert not cut.dir.exists() and not done.dir.exists() and live.dir.exists()
    live.close()
    assert not live.dir.exists()


def test_ctrl_c_in_a_task_leaves_no_part(tmp_path, monkeypatch):
    from cananalyze.fleet import task

    log = real_file(REAL_LOGS[0])
    dataset = tmp_path / "ds"

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(task, "_check_schema", interrupted)
    with pytest.raises(KeyboardInterrupt):
        process(LogTask(str(log), str(dataset), Options(checks=True)))
    assert not list(dataset.glob("*/date=*/*.parquet"))
    assert not any((dataset / layout.STAGING).iterdir())


def test_a_lost_worker_makes_its_log_failed_and_drops_its_old_parts(tmp_path):
    from cananalyze.fleet.task import record_failure

    log = str(real_file(REAL_LOGS[2]))
    dataset = tmp_path / "ds"
    assert process(LogTask(log, str(dataset), Options(checks=True)))["status"] == "ok"
    assert len(list(dataset.glob("*/date=*/*.parquet"))) == 7
    row = record_failure(dataset, log, f"{log}: worker failed: KilledWorker")
    assert row["status"] == "failed"
    logs = _table(dataset, "logs").to_pylist()
    assert [(r["source"], r["status"], r["error"]) for r in logs] == [
        (log, "failed", f"{log}: worker failed: KilledWorker")
    ]
    assert [p.parent.parent.name for p in dataset.glob("*/date=*/*.parquet")] == ["logs"]


def test_two_runs_into_one_dataset_do_not_corrupt_it(tmp_path):
    """Two writers committing the same logs at once: one whole part per table and log."""
    dataset = tmp_path / "ds"
    logs = [real_file(r) for r in REAL_LOGS[:3]]
    results: list = []

    def one_run():
        for log in logs:
            results.append(process(LogTask(str(log), str(dataset), Options(checks=True), True)))

    threads = [threading.Thread(target=one_run) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(results) == 6 and all(r["status"] == "ok" for r in results)
    for name in TABLES:
        parts = list((dataset / name).glob("date=*/*.parquet"))
        assert len(parts) == 3, name
        assert ds.dataset(parts, format="parquet").count_rows() >= 0
    logs_rows = _table(dataset, "logs").to_pylist()
    assert sorted(r["source"] for r in logs_rows) == sorted(str(p) for p in logs)


def test_query_cli_table_csv_json_and_errors(fleet, capsys):
    dataset = str(fleet["dataset"])
    sql = "SELECT status, count(*) AS n FROM logs GROUP BY status ORDER BY status"
    assert main(["query", dataset, sql, "--csv"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "status,n"
    counts = dict(line.split(",") for line in lines[1:])
    logs = _table(fleet["dataset"], "logs").to_pylist()
    assert int(counts["failed"]) == sum(r["status"] == "failed" for r in logs)
    assert main(["query", dataset, "SELECT max(date) AS d FROM frames", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["d"].count("-") == 2
    assert main(["query", dataset, "SELECT count(*) AS n FROM signals"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].strip() == "n" and "(1 row)" in out
    assert main(["query", dataset, "SELECT nope FROM logs"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("cananalyze: error: query:") and len(err.strip().splitlines()) == 1
    assert main(["query", str(fleet["root"] / "none"), "SELECT 1"]) == 2


@pytest.mark.slow
def test_fleet_cli_exit_codes(tmp_path, capsys):
    ok = real_file(REAL_LOGS[2])  # brake sensor: decodes, no violations
    out = tmp_path / "ds"
    assert main(["fleet", str(ok), "--out", str(out), "--workers", "1", "-q"]) == 0
    assert main(["fleet", str(tmp_path / "missing.log"), "--out", str(out)]) == 2
    assert "missing.log" in capsys.readouterr().err
    assert main(["fleet", str(ok), "--out", str(out), "--workers", "0"]) == 2
    bad = tmp_path / "bad.log"
    bad.write_text("not a log\n")
    assert main(["fleet", str(ok), str(bad), "--out", str(out), "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert f"failed: {bad}" in err and "1 already in the dataset" in err
    shutil.rmtree(out)


def test_export_of_a_log_without_frames_writes_empty_tables(tmp_path):
    """A BLF with no frame (python-can's writer, no message): six empty tables, not a
    traceback (the channel column's rewrite met a null column)."""
    import can

    log = tmp_path / "empty.blf"
    with can.BLFWriter(str(log)):
        pass
    assert main(["export", str(log), "--parquet", str(tmp_path / "out"), "-q"]) == 0
    for name in ("frames", "signals", "sdo", "events", "findings", "nodes"):
        assert pq.read_table(tmp_path / "out" / f"{name}.parquet").num_rows == 0, name


@pytest.mark.slow
@pytest.mark.parametrize("how, code", [("INT", 130), ("TERM", 143), ("KILL", -9)])
def test_ctrl_c_then_a_rerun_finishes_the_fleet(tmp_path, how, code):
    """SIGINT, SIGTERM or SIGKILL to a running `cananalyze fleet`: exit 130, 143 or killed,
    no part without its log's row once the next run has started, the rerun completes
    every log exactly once, and nothing is left in the staging folder."""
    import os
    import re
    import signal
    import subprocess
    import sys
    import time

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        from generate import generate
    finally:
        sys.path.pop(0)
    from cananalyze.formats.logfile import write_log

    logs = tmp_path / "logs"
    logs.mkdir()
    for i in range(24):
        write_log(generate(20_000, seed=i + 1), logs / f"run{i:02d}.log")
    dataset = tmp_path / "ds"
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root)}
    cmd = [sys.executable, "-m", "cananalyze", "fleet", str(logs), "--out", str(dataset)]
    cmd += ["--workers", "2", "-q"]
    proc = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list(dataset.glob("logs/date=*/*.parquet")) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(getattr(signal, f"SIG{how}"))
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    first = len(list(dataset.glob("logs/date=*/*.parquet")))
    assert 0 < first < 24
    rerun = subprocess.run(cmd[:-1], env=env, capture_output=True, text=True, timeout=300)
    assert rerun.returncode == 0, rerun.stderr  # the benchmark bus is healthy: no violation
    # SIGKILL can land inside a commit: the rerun finishes it (its log is then in the
    # dataset, not decoded again) or, killed after its last rename, only clears its stage
    done = re.search(r"finished (\d+) and undid", rerun.stderr)
    finished = int(done.group(1)) if done else 0
    counts = re.search(r"\((\d+) decoded, (\d+) already in the dataset\)", rerun.stderr)
    decoded, already = map(int, counts.groups())
    assert decoded + already == 24 and first <= already <= first + finished, rerun.stderr
    assert not any((dataset / layout.STAGING).iterdir())
    rows = _table(dataset, "logs").to_pylist()
    assert sorted(r["source"] for r in rows) == sorted(str(p) for p in logs.iterdir())
    for name in TABLES:
        assert len(list((dataset / name).glob("date=*/*.parquet"))) == 24, name
    assert _table(dataset, "frames").num_rows == 24 * 20_000


def test_fleet_decodes_by_a_dbc_given_on_the_command_line(tmp_path, capsys):
    """--dbc reaches every worker through Options: the brake sensor's signal in the dataset
    is cantools' value for the same frame (3.128 where the raw value is 3128)."""
    import cantools

    folder = "calumroy__CANopen_socketCAN_Test"
    log = real_file(f"{folder}/can_log_070825_brake_sensor_test1.log")
    dbc = real_file(f"{folder}/axiomatic_23123-1.dbc")
    dataset = tmp_path / "ds"
    rc = main(["fleet", str(log), "--out", str(dataset), "--dbc", str(dbc), "--workers", "1"])
    capsys.readouterr()
    assert rc in (0, 1)  # findings may make it 1; the log itself decoded
    con = duckdb.connect()
    rows = con.execute(
        "SELECT t, signal, value FROM read_parquet(?, hive_partitioning = true) "
        "WHERE signal = 'input1_value' ORDER BY t LIMIT 5",
        [str(dataset / "signals" / "**" / "*.parquet")],
    ).fetchall()
    assert rows, "no DBC signal in the dataset"
    db = cantools.database.load_file(str(dbc))
    frames = cananalyze_frames(log, db)
    for t, _, value in rows:
        assert value == pytest.approx(frames[round(t, 6)])


def cananalyze_frames(log: Path, db) -> dict[float, float]:
    """input1_value per frame time, decoded by cantools from the log's own lines (python-can
    reads the candump file: an independent reader and decoder)."""
    import can

    out = {}
    for msg in can.LogReader(str(log)):
        try:
            m = db.get_message_by_frame_id(msg.arbitration_id)
        except KeyError:
            continue
        sig = m.decode(bytes(msg.data), decode_choices=False)
        if "input1_value" in sig:
            out[round(msg.timestamp, 6)] = sig["input1_value"]
    return out


def test_a_log_without_times_is_dated_by_its_name_not_its_mtime(tmp_path):
    """Sevcon DVT dumps have no wall-clock times; can_230309_150427.txt is 23 March 2009
    by its name, whatever the copy's modification time (issue 44)."""
    log = real_file("isPointless__Sevcon/can_230309_150427.txt")
    dataset = tmp_path / "ds"
    result = run_fleet([str(log)], dataset, workers=1)
    assert result.exit_code in (0, 1)
    (row,) = _table(dataset, "logs").to_pylist()
    assert str(row["date"]) == "2009-03-23" and row["date_from"] == "name"
    assert layout.part_path(dataset, "frames", "2009-03-23", row["hash"]).is_file()
