"""What `cananalyze check` costs on top of `decode --summary` (target: at most 25 %).

Both commands run in fresh processes, interleaved, several times; for each the best
CPU time (user + system, from wait4) is kept, because on a shared machine wall time
mostly measures the neighbours. Wall times are printed too.

    python benchmarks/bench_check.py [N_FRAMES] [REPEATS] [--out DIR]   # 1e6 frames, 5 runs
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


def run(cmd: list[str]) -> tuple[float, float]:
    """(CPU seconds, wall seconds) of one child process; exit 0 or 1 (violations) is fine."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, cwd=ROOT)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise SystemExit(f"failed: {' '.join(cmd)}")
    return usage.ru_utime + usage.ru_stime, wall


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames", nargs="?", type=float, default=1e6, help="frames (default 1e6)")
    ap.add_argument("repeats", nargs="?", type=int, default=5, help="runs each (default 5)")
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where the log is generated")
    args = ap.parse_args(argv)
    n, repeats = int(args.frames), args.repeats
    args.out.mkdir(parents=True, exist_ok=True)
    stem = log_stem(args.out, n)
    log = stem.with_suffix(".log")
    if not log.exists():
        subprocess.run(
            [sys.executable, str(HERE / "generate.py"), str(n), str(stem), ".log"],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    cmds = {
        "decode --summary": [sys.executable, "-m", "cananalyze", "decode", str(log), "--summary"],
        "check": [sys.executable, "-m", "cananalyze", "check", str(log)],
    }
    best = {k: (float("inf"), float("inf")) for k in cmds}
    for _ in range(repeats):
        for name, cmd in cmds.items():
            cpu, wall = run(cmd)
            best[name] = (min(best[name][0], cpu), min(best[name][1], wall))
    for name, (cpu, wall) in best.items():
        print(f"{name:18} best CPU {cpu:6.2f} s   best wall {wall:6.2f} s")
    base, chk = best["decode --summary"][0], best["check"][0]
    print(f"check overhead: {100 * (chk / base - 1):+.1f} % CPU ({n} frames, best of {repeats})")


if __name__ == "__main__":
    main(sys.argv[1:])
