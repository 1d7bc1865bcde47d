"""`cananalyze fleet` and `query` over object storage: logs in a bucket, the dataset in a
bucket, on moto's S3 server bound to 127.0.0.1 (no other address), read back with
pyarrow's own S3 client and counted against python-can."""

from __future__ import annotations

import logging
import os
import re
import socket
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest
from conftest import real_file

pytest.importorskip("s3fs")
moto_server = pytest.importorskip("moto.server")

from cananalyze.cli.main import main  # noqa: E402
from cananalyze.fleet.schema import TABLES  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ["demo.log", "demo.blf", "faults.asc"]
REAL = [
    "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log",
    "hilch__canopen-message-interpreter/pcan1.trc",
    "hardbyte__python-can/test_CanMessage.blf",
]
CREDENTIALS = {
    "AWS_ACCESS_KEY_ID": "testing",
    "AWS_SECRET_ACCESS_KEY": "testing",
    "AWS_DEFAULT_REGION": "us-east-1",
}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def s3():
    """moto's S3 on 127.0.0.1, the AWS variables pointing at it, a bucket; stopped at the end."""
    logging.getLogger("werkzeug").setLevel(logging.ERROR)  # no line per request
    port = _free_port()
    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    endpoint = f"http://127.0.0.1:{port}"
    with pytest.MonkeyPatch.context() as mp:
        for k, v in {**CREDENTIALS, "AWS_ENDPOINT_URL": endpoint}.items():
            mp.setenv(k, v)
        import s3fs

        fs = s3fs.S3FileSystem(endpoint_url=endpoint)
        fs.mkdir("bucket")
        try:
            yield {"fs": fs, "endpoint": endpoint, "port": port}
        finally:
            server.stop()


def _arrow_fs(endpoint: str):
    """pyarrow's own S3 client (not fsspec's): the independent reader."""
    from pyarrow.fs import S3FileSystem

    return S3FileSystem(
        access_key="testing",
        secret_key="testing",
        endpoint_override=endpoint.removeprefix("http://"),
        scheme="http",
        region="us-east-1",
    )


def _table(endpoint: str, dataset: str, name: str):
    import pyarrow.dataset as ds

    return ds.dataset(
        f"{dataset}/{name}", filesystem=_arrow_fs(endpoint), format="parquet", partitioning="hive"
    ).to_table()


def _python_can_frames(path: Path) -> int:
    import can

    return sum(1 for _ in can.LogReader(str(path)))


@pytest.fixture(scope="module")
def fleet(s3, tmp_path_factory):
    """Samples and real logs uploaded to s3://bucket/logs, one fleet run into s3://bucket/ds
    through the CLI, from a working folder that must stay empty."""
    local = {f"samples/{n}": ROOT / "samples" / n for n in SAMPLES}
    for r in REAL:
        try:
            local[f"real/{Path(r).name}"] = real_file(r)
        except pytest.skip.Exception:
            continue  # the real data is not here: the samples still run
    fs = s3["fs"]
    for key, path in local.items():
        fs.put_file(str(path), f"bucket/logs/{key}")
    fs.pipe_file("bucket/logs/notes.md", b"not a log, passed over in a folder\n")
    cwd = tmp_path_factory.mktemp("cwd")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(cwd)
        rc = main(["fleet", "s3://bucket/logs", "--out", "s3://bucket/ds", "--workers", "2", "-q"])
    fs.invalidate_cache()
    return {"rc": rc, "local": local, "cwd": cwd}


def test_fleet_writes_every_log_into_the_bucket(s3, fleet):
    assert fleet["rc"] in (0, 1)  # the samples break rules on purpose: 1
    assert not list(fleet["cwd"].iterdir())  # no local ./s3:/bucket/ds
    assert not Path("s3:").exists()
    logs = _table(s3["endpoint"], "bucket/ds", "logs").to_pylist()
    expected = {f"s3://bucket/logs/{k}" for k in fleet["local"]}
    assert {r["source"] for r in logs} == expected and len(logs) == len(expected)
    assert all(r["status"] == "ok" for r in logs)
    frames = _table(s3["endpoint"], "bucket/ds", "frames")
    per_log = Counter(frames.column("source").to_pylist())
    for key, path in fleet["local"].items():
        assert per_log[f"s3://bucket/logs/{key}"] == _python_can_frames(path), key
    for r in logs:
        assert r["frames"] == per_log[r["source"]]
    assert not s3["fs"].exists("bucket/ds/_staging") or not s3["fs"].ls("bucket/ds/_staging")


def test_query_reads_the_bucket_dataset(s3, fleet, capsys, monkeypatch):
    sql = "SELECT source, frames FROM logs ORDER BY source"
    assert main(["query", "s3://bucket/ds", sql, "--csv"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "source,frames" and len(lines) == 1 + len(fleet["local"])
    got = dict(line.rsplit(",", 1) for line in lines[1:])
    for key, path in fleet["local"].items():
        assert int(got[f"s3://bucket/logs/{key}"]) == _python_can_frames(path)
    # the endpoint given as a storage option instead of the environment
    monkeypatch.delenv("AWS_ENDPOINT_URL")
    opts = f'{{"endpoint_url": "{s3["endpoint"]}"}}'
    sql = "SELECT count(*) AS n FROM frames WHERE date IS NOT NULL OR date IS NULL"
    assert main(["query", "s3://bucket/ds", sql, "--json", "--storage-options", opts]) == 0
    n = int(capsys.readouterr().out.split(":")[1].strip(" }\n"))
    assert n == sum(_python_can_frames(p) for p in fleet["local"].values())
    # or fsspec's own variable, read when fsspec is imported: a fresh process
    env = {k: v for k, v in os.environ.items() if k != "AWS_ENDPOINT_URL"}
    env.update(FSSPEC_S3_ENDPOINT_URL=s3["endpoint"], PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "cananalyze", "query", "s3://bucket/ds", sql, "--csv"]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["n", str(n)]
    assert not Path("s3:").exists()


def test_a_rerun_over_the_bucket_decodes_nothing(s3, fleet, capsys):
    rc = main(["fleet", "s3://bucket/logs", "--out", "s3://bucket/ds", "--workers", "1"])
    err = capsys.readouterr().err
    assert rc == fleet["rc"]
    n = len(fleet["local"])
    assert f"(0 decoded, {n} already in the dataset)" in err, err
    assert "no cluster" in err  # every object's size and time unchanged: none read
    s3["fs"].invalidate_cache()
    for name in TABLES:
        assert len(s3["fs"].glob(f"bucket/ds/{name}/date=*/part-*.parquet")) == n, name


def test_bad_urls_and_options_are_one_line(s3, tmp_path, capsys):
    out = str(tmp_path / "ds")
    assert main(["fleet", "nope://bucket/logs", "--out", out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown protocol 'nope'" in err[0]
    assert main(["fleet", "s3://bucket/none", "--out", out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "s3://bucket/none: no such file or folder" in err[0]
    assert main(["query", "s3://bucket/ds", "SELECT 1", "--storage-options", "{oops"]) == 2
    assert "--storage-options: not JSON" in capsys.readouterr().err
    assert main(["fleet", "compact", "s3://bucket/none"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["cananalyze: error: s3://bucket/none: not a fleet dataset (no logs table in it)"]
    assert not (tmp_path / "ds").exists()


def test_without_s3fs_the_extra_is_named(monkeypatch):
    from cananalyze.core import storage
    from cananalyze.core.extras import MissingExtra

    monkeypatch.setitem(sys.modules, "s3fs", None)
    with pytest.raises(MissingExtra, match=r"cananalyze\[s3\]"):
        storage.filesystem("s3://bucket/logs")


@pytest.mark.slow
def test_a_killed_run_then_a_rerun_completes_the_bucket_dataset(s3, tmp_path):
    """SIGKILL of `cananalyze fleet` once some logs are published in the bucket, then a
    rerun: every log once, no duplicate rows, nothing left under _staging."""
    import signal

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from generate import generate
    finally:
        sys.path.pop(0)
    from cananalyze.formats.logfile import write_log

    fs = s3["fs"]
    n = 16
    for i in range(n):
        path = tmp_path / f"run{i:02d}.log"
        write_log(generate(20_000, seed=i + 1), path)
        fs.put_file(str(path), f"bucket/kill/logs/{path.name}")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "cananalyze", "fleet", "s3://bucket/kill/logs"]
    cmd += ["--out", "s3://bucket/kill/ds", "--workers", "2", "-q"]
    proc = subprocess.Popen(cmd, env=env, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        fs.invalidate_cache()
        if fs.glob("bucket/kill/ds/logs/date=*/*.parquet"):
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=60)
    fs.invalidate_cache()
    first = len(fs.glob("bucket/kill/ds/logs/date=*/*.parquet"))
    assert 0 < first < n
    rerun = subprocess.run(
        cmd[:-1], env=env, capture_output=True, text=True, timeout=600, cwd=tmp_path
    )
    assert rerun.returncode == 0, rerun.stderr  # the benchmark bus is healthy: no violation
    # a commit cut after its manifest is finished by the rerun (on S3 the copies take a
    # while: the kill often lands there), and that log counts as already in the dataset
    counts = re.search(r"\((\d+) decoded, (\d+) already in the dataset\)", rerun.stderr)
    finished = re.search(r"finished (\d+) and undid \d+ interrupted", rerun.stderr)
    decoded, already = int(counts[1]), int(counts[2])
    assert decoded + already == n
    # (a stage whose logs part was copied before the kill, its prefix not yet deleted, is
    # finished again: counted in both)
    assert first <= already <= first + (int(finished[1]) if finished else 0), rerun.stderr
    fs.invalidate_cache()
    assert not fs.exists("bucket/kill/ds/_staging") or not fs.ls("bucket/kill/ds/_staging")
    logs = _table(s3["endpoint"], "bucket/kill/ds", "logs").to_pylist()
    assert sorted(r["source"] for r in logs) == [
        f"s3://bucket/kill/logs/run{i:02d}.log" for i in range(n)
    ]
    frames = _table(s3["endpoint"], "bucket/kill/ds", "frames")
    assert frames.num_rows == n * 20_000
    assert sorted(Counter(frames.column("source").to_pylist()).values()) == [20_000] * n
    assert not list(tmp_path.glob("s3:*"))


def test_file_urls_take_the_object_storage_path(tmp_path, monkeypatch, capsys):
    """file:// goes through fsspec like s3:// (uploads, manifest, copies): the same
    dataset as a local run, the staging prefix empty after it, a rerun that reads nothing."""
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in SAMPLES:
        (logs / name).write_bytes((ROOT / "samples" / name).read_bytes())
    monkeypatch.chdir(tmp_path)
    dataset = tmp_path / "ds"
    args = ["fleet", f"file://{logs}", "--out", f"file://{dataset}", "--workers", "1"]
    assert main(args) == 1  # the samples break rules on purpose
    capsys.readouterr()
    assert not list((dataset / "_staging").iterdir())
    import pyarrow.dataset as ds

    rows = ds.dataset(dataset / "logs", format="parquet").to_table().to_pylist()
    assert {r["source"]: r["frames"] for r in rows} == {
        f"file://{logs}/{n}": _python_can_frames(logs / n) for n in SAMPLES
    }
    assert main(args) == 1
    assert "no cluster" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds", "logs"]


class _Requests(logging.Handler):
    """The S3 server's requests counted by kind (werkzeug logs one line a request), LIST
    apart from the other GETs."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.counts: Counter[str] = Counter()

    def emit(self, record: logging.LogRecord) -> None:
        line = str(record.args[0]) if isinstance(record.args, tuple) and record.args else ""
        method, _, rest = re.sub(r"\x1b\[[0-9;]*m", "", line).partition(" ")
        listing = method == "GET" and ("list-type=" in rest or "?prefix=" in rest)
        self.counts["LIST" if listing else method] += 1


@pytest.fixture
def requests():
    """Every request the S3 server serves meanwhile, counted (the workers' too)."""
    log = logging.getLogger("werkzeug")
    counter = _Requests()
    level, propagate = log.level, log.propagate
    log.setLevel(logging.INFO)
    log.propagate = False
    log.addHandler(counter)
    try:
        yield counter.counts
    finally:
        log.removeHandler(counter)
        log.setLevel(level)
        log.propagate = propagate


def test_a_commit_lists_no_date_folders(s3, requests, capsys):
    """A log's commit finds its earlier parts from the `logs` rows the driver read once,
    not by a glob over every `date=` folder of every table: the LISTs of a run into a
    dataset of 40 date folders a table are those of a run into an empty one."""
    fs = s3["fs"]
    for name in ("demo.log", "faults.asc"):
        fs.put_file(str(ROOT / "samples" / name), f"bucket/lists/logs/{name}")
    lists = {}
    for folders in (0, 40):
        ds = f"bucket/lists/ds{folders}"
        # other days' parts (never read by a run: only the logs table is)
        fs.pipe(
            {
                f"{ds}/{t}/date=2020-01-{d + 1:02d}/part-{d:064x}.parquet": b"x"
                for t in TABLES
                if t != "logs"
                for d in range(folders)
            }
        )
        requests.clear()
        args = ["fleet", "s3://bucket/lists/logs", "--out", f"s3://{ds}", "--workers", "1"]
        assert main(args) == 1  # the samples break rules on purpose
        lists[folders] = requests["LIST"]
        assert "(2 decoded, 0 already" in capsys.readouterr().err
        fs.invalidate_cache()
        assert len(fs.glob(f"{ds}/frames/date=*/*.parquet")) == folders + 2
    assert lists[40] == lists[0], lists
    # the inputs, the logs table (before, and after to update its index), the dataset: not per log
    assert lists[0] <= 9, lists


def _generated(tmp_path: Path, n: int, frames: int = 2000, seed: int = 1) -> list[Path]:
    """`n` generated candump logs of one day (benchmarks/generate.py's bus)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from generate import generate
    finally:
        sys.path.pop(0)
    from cananalyze.formats.logfile import write_log

    out = []
    for i in range(n):
        path = tmp_path / f"gen{seed + i:02d}.log"
        write_log(generate(frames, seed=seed + i), path)
        out.append(path)
    return out


def _counts(dataset: str, table: str) -> Counter:
    """Rows of `table` by (source, hash), as `cananalyze query` reads them."""
    from cananalyze.fleet.query import query

    _, rows = query(
        dataset, f"SELECT source::VARCHAR, hash::VARCHAR, count(*) FROM {table} GROUP BY ALL"
    )
    return Counter({(s, h): n for s, h, n in rows})


def _keys(fs, prefix: str) -> list[str]:
    fs.invalidate_cache()
    return sorted(k for k in fs.find(prefix) if k.endswith(".parquet"))


@pytest.mark.slow  # fleet runs and a compaction, end to end
def test_compact_on_the_bucket_keeps_every_row_once_for_a_reader_meanwhile(
    s3, tmp_path, monkeypatch, capsys
):
    """`fleet compact s3://...`: each table's day becomes one time-ordered file, every row
    and its lineage kept; a `query` run at the worst moment (the new file copied in, its
    inputs not yet deleted) sees every row once; a rerun skips every log from the
    compacted rows, and a changed log's old rows leave the compacted files."""
    from cananalyze.fleet import layout

    fs = s3["fs"]
    for path in _generated(tmp_path, 4):
        fs.put_file(str(path), f"bucket/c/logs/{path.name}")
    ds = "s3://bucket/c/ds"
    run = ["fleet", "s3://bucket/c/logs", "--out", ds, "--workers", "1"]
    assert main([*run, "-q"]) == 0
    before = {t: _counts(ds, t) for t in TABLES}
    assert len(before["logs"]) == 4
    assert len(_keys(fs, "bucket/c/ds/frames")) == 4

    seen = []
    deleted = layout._delete_after

    def reader_first(fs_, after):  # what a reader sees just before the inputs go
        if after:
            table = after[0].split("/c/ds/")[1].split("/")[0]
            raw = len(_keys(fs, f"bucket/c/ds/{table}"))  # a plain listing: both copies
            seen.append((table, raw, _counts(ds, table)))
        deleted(fs_, after)

    monkeypatch.setattr(layout, "_delete_after", reader_first)
    assert main(["fleet", "compact", ds]) == 0
    monkeypatch.undo()
    assert "compact: 28 files" in capsys.readouterr().err
    assert {t for t, _, _ in seen} == set(TABLES)
    for table, raw, counted in seen:
        assert raw == 4 + 1, table  # the inputs and the new file, listed together
        assert counted == before[table], table  # yet `query` reads each row once
    for table in TABLES:
        (key,) = _keys(fs, f"bucket/c/ds/{table}")
        assert key.split("/")[-1].startswith("part-compact-"), key
        assert _counts(ds, table) == before[table], table
    assert not _keys(fs, "bucket/c/ds/_staging")
    import pyarrow.parquet as pq

    with fs.open(_keys(fs, "bucket/c/ds/frames")[0]) as f:
        t = pq.read_table(f, columns=["t"]).column("t").to_numpy()
    assert (t[1:] >= t[:-1]).all()  # rows in time order

    assert main(run) == 0
    err = capsys.readouterr().err
    assert "(0 decoded, 4 already in the dataset)" in err and "no cluster" in err, err
    # a changed log: its new rows in, its old ones out of the compacted files
    (tmp_path / "x").mkdir()
    (changed,) = _generated(tmp_path / "x", 1, frames=700, seed=9)
    fs.put_file(str(changed), "bucket/c/logs/gen01.log")
    assert main([*run, "-q"]) == 0
    after = _counts(ds, "frames")
    mine = {h: n for (s, h), n in after.items() if s == "s3://bucket/c/logs/gen01.log"}
    assert list(mine.values()) == [700], after
    assert {k: n for k, n in after.items() if k[0] != "s3://bucket/c/logs/gen01.log"} == {
        k: n for k, n in before["frames"].items() if k[0] != "s3://bucket/c/logs/gen01.log"
    }
    assert len(_counts(ds, "logs")) == 4


@pytest.mark.slow  # three fleet runs into a bucket, end to end
def test_batch_on_the_bucket_shares_parts(s3, tmp_path, capsys):
    """`--batch 4` into a bucket: the four small logs of one day share one file a table,
    with the rows a one-log-a-task run writes; a rerun skips them all."""
    fs = s3["fs"]
    for path in _generated(tmp_path, 4, seed=21):
        fs.put_file(str(path), f"bucket/b/logs/{path.name}")
    common = ["fleet", "s3://bucket/b/logs", "--workers", "1", "-q"]
    assert main([*common, "--out", "s3://bucket/b/one"]) == 0
    assert main([*common, "--out", "s3://bucket/b/batched", "--batch", "4"]) == 0
    for table in TABLES:
        assert _counts("s3://bucket/b/batched", table) == _counts("s3://bucket/b/one", table)
        (key,) = _keys(fs, f"bucket/b/batched/{table}")
        assert key.split("/")[-1].startswith("part-compact-"), key
    assert not _keys(fs, "bucket/b/batched/_staging")
    capsys.readouterr()
    assert main([*common[:-1], "--out", "s3://bucket/b/batched", "--batch", "4"]) == 0
    assert "(0 decoded, 4 already in the dataset)" in capsys.readouterr().err
    # decoded again, batched again: the earlier copies leave the shared files first
    assert main([*common, "--out", "s3://bucket/b/batched", "--batch", "4", "--force"]) == 0
    for table in TABLES:
        assert _counts("s3://bucket/b/batched", table) == _counts("s3://bucket/b/one", table)


def test_a_rerun_reads_the_logs_index_with_one_request(s3, fleet, requests, capsys):
    """The driver's one read of the `logs` table at a URL: its listing and one GET, the
    index the run that wrote the parts left (fleet/logsindex); no HEAD a file, nothing
    else read, no cluster. Without the index: one GET a `logs` part (fetched
    concurrently), and one PUT writing the index again for the next rerun."""
    rerun = ["fleet", "s3://bucket/logs", "--out", "s3://bucket/ds", "--workers", "1"]
    requests.clear()
    assert main(rerun) in (0, 1)
    assert "no cluster" in capsys.readouterr().err
    n = len(fleet["local"])
    assert requests["GET"] == 1 and "PUT" not in requests, dict(requests)
    assert requests["HEAD"] <= 3 and requests["LIST"] <= 8, dict(requests)
    s3["fs"].rm("bucket/ds/_index/logs.parquet")
    requests.clear()
    assert main(rerun) in (0, 1)
    assert f"(0 decoded, {n} already in the dataset)" in capsys.readouterr().err
    assert requests["GET"] in (n, n + 1) and requests["PUT"] == 1, dict(requests)
    requests.clear()
    assert main(rerun) in (0, 1)
    assert requests["GET"] == 1 and "PUT" not in requests, dict(requests)


def test_logs_rows_at_a_url_read_an_older_part_s_missing_columns_as_null(tmp_path):
    """A `logs` part written before a column was added: that column null, the rest read."""
    import pyarrow.parquet as pq

    from cananalyze.fleet.task import logs_rows

    logs = tmp_path / "logs" / "date=2024-03-13"
    logs.mkdir(parents=True)
    row = {"source": ["/x.log"], "hash": ["ab"], "status": ["ok"], "frames": [5]}
    pq.write_table(__import__("pyarrow").table(row), logs / "part-ab.parquet")
    (got,) = logs_rows(f"file://{tmp_path}")["/x.log"]
    assert got["hash"] == "ab" and got["frames"] == 5 and got["date"] == "2024-03-13"
    assert got["mtime_ns"] is None and got["config"] is None
