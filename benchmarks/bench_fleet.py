"""`cananalyze fleet` on a generated fleet, local and on a local S3 server: CPU per task and per frame, reruns, bytes.

LOGS generated logs (generate.py's network, one seed per log, days apart so the dataset
has several date partitions; 3 in 5 candump, 1 in 5 ASC, 1 in 5 BLF) of FRAMES frames,
or of sizes cycling through a list (`1e3,1e4,1e5`), so each run's logs table gives a
least-squares line of a task's CPU against its frames: the intercept is the fixed cost
of a task (open, hash, pipeline set-up, the commit of seven parts), the slope the CPU of
a frame. Each run is a fresh `cananalyze fleet` process into an empty dataset, then the
same command again (a rerun: every log already there). Storages (`local`, `s3`) and
worker counts are interleaved run by run (the machine is shared: wall time swings) and
each figure is the median over the rounds.

CPU is user + system of the whole process tree (wait4: the Dask workers are joined
children), beside wall; the tasks' own CPU and the workers' peak resident memory come
from the dataset's `logs` table (read with pyarrow). `s3`: the logs and the dataset in a
bucket of moto's S3 server, in this process on 127.0.0.1 (its CPU is ours, counted apart),
each request counted by its method from the server's request log.

    python benchmarks/bench_fleet.py [LOGS] [FRAMES[,FRAMES...]] [--workers 1,2]
        [--storage local,s3] [--repeats N] [--out DIR]
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import resource
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from generate import VERSION, generate, write_asc  # noqa: E402

from cananalyze.formats.logfile import write_log  # noqa: E402

DAY = 86_400.0
BUCKET = "bench"
CREDENTIALS = {
    "AWS_ACCESS_KEY_ID": "testing",
    "AWS_SECRET_ACCESS_KEY": "testing",
    "AWS_DEFAULT_REGION": "us-east-1",
}


def make_fleet(folder: Path, logs: int, sizes: list[int]) -> dict[str, int]:
    """The logs (kept between runs when the same fleet is asked again); counts per format."""
    stamp = folder / f".made-v{VERSION}-{logs}x{'-'.join(map(str, sizes))}"
    kinds = {".log": 0, ".asc": 0, ".blf": 0}
    suffixes = [(".blf" if i % 5 == 0 else ".asc" if i % 5 == 1 else ".log") for i in range(logs)]
    for s in suffixes:
        kinds[s] += 1
    if stamp.exists():
        return kinds
    shutil.rmtree(folder, ignore_errors=True)
    for i, suffix in enumerate(suffixes):
        batch = generate(sizes[i % len(sizes)], seed=i + 1)
        batch.t[:] += (i % 7) * DAY  # a week of logs: seven date partitions
        path = folder / f"logger{i % 10:02d}" / f"run{i:05d}{suffix}"
        path.parent.mkdir(parents=True, exist_ok=True)
        if not (suffix == ".asc" and write_asc(batch, path)):
            write_log(batch, path)
    stamp.touch()
    return kinds


class Requests(logging.Handler):
    """Counts the S3 server's requests by method (werkzeug logs one line per request)."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.counts: Counter[str] = Counter()

    def emit(self, record: logging.LogRecord) -> None:
        line = str(record.args[0]) if isinstance(record.args, tuple) and record.args else ""
        line = re.sub(r"\x1b\[[0-9;]*m", "", line)  # werkzeug colours some lines
        method, _, rest = line.partition(" ")
        if method in ("GET", "HEAD", "PUT", "POST", "DELETE"):
            listing = method == "GET" and ("list-type=" in rest or "?prefix=" in rest)
            self.counts["LIST" if listing else method] += 1


def start_s3():
    """(moto's S3 server started on a free port of 127.0.0.1, its `Requests` counter, its
    endpoint URL)."""
    from moto.server import ThreadedMotoServer

    requests = Requests()
    log = logging.getLogger("werkzeug")
    log.setLevel(logging.INFO)
    log.addHandler(requests)
    log.propagate = False
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    return server, requests, f"http://127.0.0.1:{port}"


class S3:
    """moto's S3 server on 127.0.0.1 with one bucket, the logs uploaded under `logs/`."""

    def __init__(self, folder: Path) -> None:
        self.server, self.requests, url = start_s3()
        self.env = {**CREDENTIALS, "AWS_ENDPOINT_URL": url}
        import s3fs

        self.fs = s3fs.S3FileSystem(
            endpoint_url=self.env["AWS_ENDPOINT_URL"], key="testing", secret="testing"
        )
        self.fs.mkdir(BUCKET)
        for path in sorted(folder.rglob("run*")):
            self.fs.put_file(str(path), f"{BUCKET}/logs/{path.relative_to(folder)}")

    def stop(self) -> None:
        self.server.stop()


def run_fleet(logs: str, dataset: str, workers: int, env: dict) -> tuple[float, float]:
    """(CPU seconds of the process tree, wall seconds) of one `cananalyze fleet` process."""
    cmd = [sys.executable, "-m", "cananalyze", "fleet", logs, "--out", dataset]
    cmd += ["--workers", str(workers), "-q"]
    env = {**os.environ, **env}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")
    env.setdefault("PYTHONFAULTHANDLER", "1")  # a fatal error's traceback, onto stderr
    t = time.perf_counter()
    with tempfile.TemporaryFile() as err:  # kept: a failure shows its last lines
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        if os.waitstatus_to_exitcode(status) not in (0, 1):
            err.seek(0)
            tail = err.read().decode("utf-8", "replace").splitlines()[-25:]
            raise SystemExit(f"failed ({status}): {' '.join(cmd)}\n" + "\n".join(tail))
    return usage.ru_utime + usage.ru_stime, wall


def dataset_figures(fs, dataset: str) -> dict:
    """From the dataset's `logs` table and its files: counts, task CPU, the per-task fit, bytes."""
    import pyarrow as pa
    import pyarrow.dataset as ds

    dates = ds.partitioning(pa.schema([("date", pa.date32())]), flavor="hive")
    logs = ds.dataset(f"{dataset}/logs", filesystem=fs, format="parquet", partitioning=dates)
    t = logs.to_table(columns=["frames", "cpu_seconds", "peak_rss_mb", "status", "date"])
    frames = np.asarray(t.column("frames").to_numpy(zero_copy_only=False), float)
    cpu = np.asarray(t.column("cpu_seconds").to_numpy(zero_copy_only=False), float)
    fit = np.polyfit(frames, cpu, 1) if len(set(frames)) > 1 else (np.nan, np.nan)
    files = [f for f in fs.find(dataset, detail=True).values() if f["name"].endswith(".parquet")]
    return {
        "logs": t.num_rows,
        "frames": int(frames.sum()),
        "task_cpu": float(cpu.sum()),
        "per_frame_us": float(fit[0]) * 1e6,
        "per_task_ms": float(fit[1]) * 1e3,
        "peak_mb": float(max(t.column("peak_rss_mb").to_pylist())),
        "failed": sum(s != "ok" for s in t.column("status").to_pylist()),
        "dates": len(set(t.column("date").to_pylist())),
        "bytes": sum(f["size"] for f in files if "/_staging/" not in f["name"]),
    }


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="?", type=int, default=30, help="logs (default 30)")
    ap.add_argument(
        "frames", nargs="?", default="1e3,1e4,1e5", help="frames a log, or sizes to cycle"
    )
    ap.add_argument("--workers", default="1,2", help="worker counts, interleaved (default 1,2)")
    ap.add_argument("--storage", default="local,s3", help="local, s3 or both (default)")
    ap.add_argument("--repeats", type=int, default=3, help="rounds; figures are medians (3)")
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where logs and dataset go")
    args = ap.parse_args(argv)
    sizes = [int(float(f)) for f in args.frames.split(",")]
    counts = [int(w) for w in args.workers.split(",")]
    storages = args.storage.split(",")
    folder = args.out / "fleet_logs"
    t = time.perf_counter()
    kinds = make_fleet(folder, args.logs, sizes)
    total = sum(sizes[i % len(sizes)] for i in range(args.logs))
    size = sum(p.stat().st_size for p in folder.rglob("run*"))
    shape = (
        f"x {sizes[0]:,} frames"
        if len(sizes) == 1
        else f"of {'/'.join(f'{s:,}' for s in sizes)} frames"
    )
    print(
        f"fleet: {args.logs} logs {shape} = {total:,} frames ({kinds['.log']} candump, "
        f"{kinds['.asc']} ASC, {kinds['.blf']} BLF), {size / 1e6:.1f} MB, "
        f"{size / total:.1f} bytes a frame, made in {time.perf_counter() - t:.1f} s"
    )
    import fsspec

    s3 = S3(folder) if "s3" in storages else None
    where = {"local": (fsspec.filesystem("file"), str(folder), str(args.out / "fleet_dataset"), {})}
    if s3 is not None:
        where["s3"] = (s3.fs, f"s3://{BUCKET}/logs", f"{BUCKET}/ds", s3.env)
    runs: dict[tuple[str, int], list[dict]] = {}
    try:
        for r in range(args.repeats):
            for storage in storages:
                fs, logs, dataset, env = where[storage]
                out = f"s3://{dataset}" if storage == "s3" else dataset
                for w in counts:
                    if fs.exists(dataset):
                        fs.rm(dataset, recursive=True)
                    fs.invalidate_cache()
                    load = os.getloadavg()[0]
                    fig: dict = {}
                    for step in ("", "rerun_"):
                        if s3 is not None:
                            s3.requests.counts.clear()
                        own = resource.getrusage(resource.RUSAGE_SELF)
                        cpu, wall = run_fleet(logs, out, w, env)
                        mine = resource.getrusage(resource.RUSAGE_SELF)
                        fig[step + "cpu"], fig[step + "wall"] = cpu, wall
                        if storage == "s3":
                            fig[step + "requests"] = dict(s3.requests.counts)
                            fig[step + "server_cpu"] = (mine.ru_utime + mine.ru_stime) - (
                                own.ru_utime + own.ru_stime
                            )
                    fs.invalidate_cache()
                    fig |= dataset_figures(fs, dataset)
                    if fig["logs"] != args.logs or fig["frames"] != total or fig["failed"]:
                        raise SystemExit(f"{storage} workers={w}: the dataset is incomplete: {fig}")
                    runs.setdefault((storage, w), []).append(fig)
                    requests = ""
                    if storage == "s3":
                        requests = (
                            f", requests {_requests(fig['requests'])}, rerun "
                            f"{_requests(fig['rerun_requests'])}, S3 server CPU "
                            f"{fig['server_cpu']:.2f} s"
                        )
                    print(
                        f"run {r + 1} {storage} workers={w}: wall {fig['wall']:.2f} s, CPU {fig['cpu']:.2f} s "
                        f"(user+sys, all processes), tasks CPU {fig['task_cpu']:.2f} s, a task "
                        f"{fig['per_task_ms']:.0f} ms + {fig['per_frame_us']:.2f} us a frame, peak "
                        f"worker RSS {fig['peak_mb']:.0f} MB, dataset {fig['bytes'] / 1e6:.1f} MB "
                        f"in {fig['dates']} date partitions; rerun wall {fig['rerun_wall']:.2f} s, "
                        f"CPU {fig['rerun_cpu']:.2f} s{requests}; load average {load:.1f} before, "
                        f"{os.getloadavg()[0]:.1f} after"
                    )
    finally:
        if s3 is not None:
            s3.stop()
    for (storage, w), figs in runs.items():
        m = {
            k: statistics.median(f[k] for f in figs) for k in figs[0] if not k.endswith("requests")
        }
        n = args.logs
        line = (
            f"median {storage} workers={w} ({len(figs)} runs): wall {m['wall']:.2f} s, CPU "
            f"{m['cpu']:.2f} s, {total / m['cpu'] / 1e3:,.0f}k frames a CPU second; tasks CPU "
            f"{m['task_cpu']:.2f} s, a task {m['per_task_ms']:.0f} ms + {m['per_frame_us']:.2f} us a "
            f"frame; outside the tasks (driver, cluster start, Dask, the commits) "
            f"{(m['cpu'] - m['task_cpu']) / n * 1e3:.0f} ms a log; rerun (start-up included) wall "
            f"{m['rerun_wall']:.2f} s, CPU {m['rerun_cpu']:.2f} s; peak worker RSS {m['peak_mb']:.0f} MB; "
            f"dataset {m['bytes'] / total:.1f} bytes a frame"
        )
        if storage == "s3":
            first, again = (
                _median_counts([f[k] for f in figs]) for k in ("requests", "rerun_requests")
            )
            line += (
                f"; requests a log {sum(first.values()) / n:.1f} ({_requests(first, n)}), "
                f"rerun {sum(again.values()) / n:.2f} a log; S3 server CPU {m['server_cpu']:.2f} s"
            )
        print(line)
    for storage in storages:
        if (storage, 1) in runs and (storage, 2) in runs:
            walls = [statistics.median(f["wall"] for f in runs[storage, w]) for w in (1, 2)]
            print(f"speed-up 2 vs 1 workers ({storage}, medians): {walls[0] / walls[1]:.2f}x wall")


def _median_counts(runs: list[dict]) -> dict:
    """Each method's median count over the runs."""
    return {k: statistics.median(r.get(k, 0) for r in runs) for k in set().union(*runs)}


def _requests(counts: dict, per: int = 1) -> str:
    return " ".join(f"{k} {v / per:.3g}" for k, v in sorted(counts.items())) or "none"


if __name__ == "__main__":
    main(sys.argv[1:])
