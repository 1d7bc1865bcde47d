"""`cananalyze fleet` on a generated fleet with 1 and 2 local workers: frames/s, CPU, memory per worker.

LOGS generated logs of FRAMES frames each (generate.py's network, one seed per log,
days apart so the dataset has several date partitions; 3 in 5 candump, 1 in 5
ASC, 1 in 5 BLF). Each run is a fresh `cananalyze fleet` process into an empty
dataset, worker counts interleaved run by run (the machine is shared: wall time
swings). CPU is user + system of the whole process tree (wait4: the Dask workers
are joined children), beside wall; the tasks' own CPU and the workers' peak
resident memory come from the dataset's `logs` table (read with DuckDB).

    python benchmarks/bench_fleet.py [LOGS] [FRAMES] [--workers 1,2] [--repeats N] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE))

from generate import generate, write_asc  # noqa: E402

from cananalyze.formats.logfile import write_log  # noqa: E402

DAY = 86_400.0


def make_fleet(folder: Path, logs: int, frames: int) -> dict[str, int]:
    """The logs (kept between runs when the same size is asked again); counts per format."""
    stamp = folder / f".made-{logs}x{frames}"
    kinds = {".log": 0, ".asc": 0, ".blf": 0}
    suffixes = [(".blf" if i % 5 == 0 else ".asc" if i % 5 == 1 else ".log") for i in range(logs)]
    for s in suffixes:
        kinds[s] += 1
    if stamp.exists():
        return kinds
    shutil.rmtree(folder, ignore_errors=True)
    for i, suffix in enumerate(suffixes):
        batch = generate(frames, seed=i + 1)
        batch.t[:] += (i % 7) * DAY  # a week of logs: seven date partitions
        path = folder / f"logger{i % 10:02d}" / f"run{i:05d}{suffix}"
        path.parent.mkdir(parents=True, exist_ok=True)
        if not (suffix == ".asc" and write_asc(batch, path)):
            write_log(batch, path)
    stamp.touch()
    return kinds


def run_fleet(folder: Path, dataset: Path, workers: int) -> tuple[float, float]:
    """(CPU seconds of the process tree, wall seconds) of one fleet run into an empty dataset."""
    shutil.rmtree(dataset, ignore_errors=True)
    cmd = [sys.executable, "-m", "cananalyze", "fleet", str(folder), "--out", str(dataset)]
    cmd += ["--workers", str(workers), "-q"]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    t = time.perf_counter()
    proc = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise SystemExit(f"failed ({status}): {' '.join(cmd)}")
    return usage.ru_utime + usage.ru_stime, wall


def dataset_figures(dataset: Path) -> dict:
    import duckdb

    con = duckdb.connect()
    logs = str(dataset / "logs" / "*" / "*.parquet")
    row = con.execute(
        "SELECT count(*), sum(frames), sum(cpu_seconds), sum(seconds), "
        "max(peak_rss_mb), count(*) FILTER (WHERE status <> 'ok'), count(DISTINCT date) "
        f"FROM read_parquet('{logs}', hive_partitioning = true)"
    ).fetchone()
    size = sum(p.stat().st_size for p in dataset.rglob("*.parquet"))
    keys = ("logs", "frames", "task_cpu", "task_wall", "peak_mb", "failed", "dates")
    return {**dict(zip(keys, row, strict=True)), "bytes": size}


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="?", type=int, default=300, help="logs (default 300)")
    ap.add_argument("frames", nargs="?", type=float, default=1e4, help="frames a log (1e4)")
    ap.add_argument("--workers", default="1,2", help="worker counts, interleaved (default 1,2)")
    ap.add_argument("--repeats", type=int, default=2, help="runs each (default 2)")
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where logs and dataset go")
    args = ap.parse_args(argv)
    frames = int(args.frames)
    counts = [int(w) for w in args.workers.split(",")]
    folder = args.out / "fleet_logs"
    dataset = args.out / "fleet_dataset"
    t = time.perf_counter()
    kinds = make_fleet(folder, args.logs, frames)
    size = sum(p.stat().st_size for p in folder.rglob("run*"))
    print(
        f"fleet: {args.logs} logs x {frames:,} frames = {args.logs * frames:,} frames "
        f"({kinds['.log']} candump, {kinds['.asc']} ASC, {kinds['.blf']} BLF), "
        f"{size / 1e6:.1f} MB, made in {time.perf_counter() - t:.1f} s"
    )
    best: dict[int, tuple[float, float, dict]] = {}
    for r in range(args.repeats):
        for w in counts:
            load = os.getloadavg()[0]
            cpu, wall = run_fleet(folder, dataset, w)
            fig = dataset_figures(dataset)
            if fig["logs"] != args.logs or fig["frames"] != args.logs * frames or fig["failed"]:
                raise SystemExit(f"workers={w}: the dataset is incomplete: {fig}")
            print(
                f"run {r + 1} workers={w}: wall {wall:.2f} s, CPU {cpu:.2f} s (user+sys, all "
                f"processes), {fig['frames'] / wall:,.0f} frames/s, tasks CPU "
                f"{fig['task_cpu']:.2f} s, peak worker RSS {fig['peak_mb']:.0f} MB, dataset "
                f"{fig['bytes'] / 1e6:.1f} MB in {fig['dates']} date partitions, load average "
                f"{load:.1f} before, {os.getloadavg()[0]:.1f} after"
            )
            if w not in best or wall < best[w][1]:
                best[w] = (cpu, wall, fig)
    for w, (cpu, wall, fig) in sorted(best.items()):
        print(
            f"best workers={w}: wall {wall:.2f} s, CPU {cpu:.2f} s, {fig['frames'] / wall:,.0f} "
            f"frames/s, {args.logs / wall:.1f} logs/s, peak worker RSS {fig['peak_mb']:.0f} MB"
        )
    if 1 in best and 2 in best:
        print(f"speed-up 2 vs 1 workers: {best[1][1] / best[2][1]:.2f}x wall")


if __name__ == "__main__":
    main(sys.argv[1:])
