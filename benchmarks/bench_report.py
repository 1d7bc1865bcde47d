"""What `cananalyze report` costs beside `check` on the same log, and the page's size.

The report runs the same checks and adds its own sink (statistics over every frame,
plots decimated to a pixel's min and max), so its cost is measured against `check`,
in fresh processes, interleaved, the best of several runs each: CPU seconds
(user + system, from wait4) beside wall seconds, and the peak RSS. The page must stay
a few MB whatever the log's length.

    python benchmarks/bench_report.py [N_FRAMES] [REPEATS] [--out DIR]   # 1e6 frames, 3 runs
    python benchmarks/bench_report.py 10e6 2                             # the issue's 10M
    python benchmarks/bench_report.py 10e6 1 --out ../main/benchmarks/out --page /tmp  # reuse a log
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


def run(cmd: list[str]) -> tuple[float, float, float]:
    """(CPU seconds, wall seconds, peak RSS MB) of one child; exit 0 or 1 (violations) is fine."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, cwd=ROOT, env=ENV)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        raise SystemExit(f"failed: {' '.join(cmd)}")
    return usage.ru_utime + usage.ru_stime, wall, usage.ru_maxrss / 1024


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames", nargs="?", type=float, default=1e6, help="frames (default 1e6)")
    ap.add_argument("repeats", nargs="?", type=int, default=3, help="runs each (default 3)")
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where the log is generated")
    ap.add_argument(
        "--page", type=Path, help="where the page is written (default: --out; for a read-only log)"
    )
    args = ap.parse_args(argv)
    n, repeats = int(args.frames), args.repeats
    args.out.mkdir(parents=True, exist_ok=True)
    log = log_stem(args.out, n).with_suffix(".log")
    if not log.exists():
        subprocess.run(
            [
                sys.executable,
                str(HERE / "generate.py"),
                str(n),
                str(log_stem(args.out, n)),
                ".log",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    (args.page or args.out).mkdir(parents=True, exist_ok=True)
    page = (args.page or args.out) / log_stem(Path(), n).with_suffix(".html").name
    devices = [a for k in range(1, 17) for a in ("--device", f"{k}=dat7014")]
    cli = [sys.executable, "-m", "cananalyze"]
    cmds = {
        "check": [*cli, "check", str(log), "-q", *devices],
        "report": [*cli, "report", str(log), "-o", str(page), "-q", *devices],
    }
    best = {k: (float("inf"), float("inf"), 0.0) for k in cmds}
    for _ in range(repeats):
        for name, cmd in cmds.items():
            cpu, wall, mb = run(cmd)
            b = best[name]
            best[name] = (min(b[0], cpu), min(b[1], wall), max(b[2], mb))
    with open(log, "rb") as f:
        first = f.readline().split()[0].strip(b"()")
        f.seek(max(0, log.stat().st_size - 200))
        last = f.read().splitlines()[-1].split()[0].strip(b"()")
    span = float(last) - float(first)
    for name, (cpu, wall, mb) in best.items():
        print(f"{name:8} best CPU {cpu:7.2f} s   best wall {wall:7.2f} s   peak RSS {mb:7.0f} MB")
    extra = best["report"][0] / best["check"][0] - 1
    print(
        f"report overhead: {100 * extra:+.1f} % CPU ({n} frames, {span:.0f} s of log, best of {repeats})"
    )
    print(f"page: {page.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main(sys.argv[1:])
