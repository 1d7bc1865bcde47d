"""What `cananalyze report` costs beside `check` on the same log, and the page's size.

The report runs the same checks and adds its own sink (statistics over every frame,
plots decimated to a pixel's min and max), so its cost is measured against `check`,
in fresh processes, interleaved, the best of several runs each: CPU seconds
(user + system, from wait4) beside wall seconds, and the peak RSS. The page must stay
a few MB whatever the log's length, on a healthy bus and on a faulty one (the
generator's `--faults` bus breaks a rule every few frames: its findings are most of a
page).

    python benchmarks/bench_report.py [N_FRAMES] [REPEATS] [--out DIR]   # 1e6 frames, 3 runs
    python benchmarks/bench_report.py 10e6 2 --bus both                  # the issue's 10M
    python benchmarks/bench_report.py 10e6 1 --out /work/benchout --page /tmp --against ../base
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # benchmarks/: the generator's log names
from generate import log_stem  # noqa: E402

ROOT = HERE.parent
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def run(cmd: list[str], tree: Path) -> tuple[float, float, float]:
    """(CPU seconds, wall seconds, peak RSS MB) of one child run from `tree`'s code;
    exit 0 or 1 (violations) is fine."""
    t = time.perf_counter()
    env = {**ENV, "PYTHONPATH": str(tree)}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, cwd=tree, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise SystemExit(f"failed: {' '.join(cmd)}")
    return usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024


def the_log(out: Path, n: int, bus: str) -> Path:
    """The n-frame log of this bus, generated once: the healthy one under the generator's
    versioned names (the ones bench_decode reads)."""
    stem = log_stem(out, n, faults=bus == "faulty")
    log = stem.with_suffix(".log")
    if not log.exists():
        flags = ["--faults"] if bus == "faulty" else []
        cmd = [sys.executable, str(HERE / "generate.py"), str(n), str(stem), ".log", *flags]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return log


def span(log: Path) -> float:
    """Seconds from the log's first frame to its last (candump's time stamps)."""
    with open(log, "rb") as f:
        first = f.readline().split()[0].strip(b"()")
        f.seek(max(0, log.stat().st_size - 200))
        last = f.read().splitlines()[-1].split()[0].strip(b"()")
    return float(last) - float(first)


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames", nargs="?", type=float, default=1e6, help="frames (default 1e6)")
    ap.add_argument("repeats", nargs="?", type=int, default=3, help="runs each (default 3)")
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where the log is generated")
    ap.add_argument(
        "--page", type=Path, help="where the page is written (default: --out; for a read-only log)"
    )
    ap.add_argument(
        "--bus",
        choices=("healthy", "faulty", "both"),
        default="healthy",
        help="the generator's healthy bus, its faulty one (--faults), or both (default healthy)",
    )
    ap.add_argument(
        "--against",
        type=Path,
        help="another checkout (its helper built): its report and check too, interleaved",
    )
    args = ap.parse_args(argv)
    n, repeats = int(args.frames), args.repeats
    args.out.mkdir(parents=True, exist_ok=True)
    (args.page or args.out).mkdir(parents=True, exist_ok=True)
    trees = {"this": ROOT}
    if args.against is not None:
        trees["other"] = args.against.resolve()
        if not (trees["other"] / "cananalyze" / "__init__.py").is_file():
            ap.error(f"--against {args.against}: no cananalyze package there")
    devices = [a for k in range(1, 17) for a in ("--device", f"{k}=dat7014")]
    cli = [sys.executable, "-m", "cananalyze"]
    for bus in ("healthy", "faulty") if args.bus == "both" else (args.bus,):
        log = the_log(args.out, n, bus)
        pages = {tree: (args.page or args.out) / f"report_{tree}_{log.stem}.html" for tree in trees}
        cmds = {
            (tree, name): cmd
            for tree in trees
            for name, cmd in (
                ("check", [*cli, "check", str(log), "-q", *devices]),
                ("report", [*cli, "report", str(log), "-o", str(pages[tree]), "-q", *devices]),
            )
        }
        best = {k: (float("inf"), float("inf"), 0.0) for k in cmds}
        for _ in range(repeats):
            for (tree, name), cmd in cmds.items():
                cpu, wall, mb = run(cmd, trees[tree])
                b = best[tree, name]
                best[tree, name] = (min(b[0], cpu), min(b[1], wall), max(b[2], mb))
        print(f"{bus} bus: {log.name}, {n} frames, {span(log):.0f} s of log, best of {repeats}")
        for tree, path in trees.items():
            where = "" if len(trees) == 1 else f"  [{tree} tree: {path}]"
            for name in ("check", "report"):
                cpu, wall, mb = best[tree, name]
                print(
                    f"  {name:7} CPU {cpu:7.2f} s   wall {wall:7.2f} s   peak RSS {mb:6.0f} MB{where}"
                )
            ratio = best[tree, "report"][0] / best[tree, "check"][0]
            size = pages[tree].stat().st_size / 1e6
            print(f"  report/check CPU {ratio:.2f}   page {size:.2f} MB{where}")


if __name__ == "__main__":
    main(sys.argv[1:])
