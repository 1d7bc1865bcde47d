"""Every performance target of issue 10 in one command, ratios first.

Each measurement is a fresh `python -m cananalyze` process (whole-process wall
time and peak RSS), repeated `--repeat` times, best kept: other work on the
machine only ever makes a run slower. python-can's `LogReader` iterates the same
file in the same run, so the ratio does not depend on how busy the machine is.

    python benchmarks/bench_decode.py                      # 1M frames, candump/ASC/BLF
    python benchmarks/bench_decode.py --sizes 1e6,10e6     # + peak RSS at 10M (candump)
    python benchmarks/bench_decode.py --sizes 1e6,10e6,50e6 --formats .log

Reported: decode --summary frames/s per format and the python-can ratio; text
output lines/s (`decode -o FILE`); `check` overhead when that sub-command
exists; peak RSS per size; `cananalyze --help` start-up time.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = HERE / "out"
TARGETS = {".log": 3e6, ".asc": 2e6, ".blf": 3e6}


def run_process(cmd: list[str]) -> tuple[float, float, int]:
    """Wall seconds, peak RSS (MB) and exit code of a child process."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    _, status, usage = os.wait4(proc.pid, 0)
    return time.perf_counter() - t, usage.ru_maxrss / 1024, os.waitstatus_to_exitcode(status)


def best(cmd: list[str], repeat: int, ok=(0,)) -> tuple[float, float]:
    runs = []
    for _ in range(repeat):
        wall, mb, code = run_process(cmd)
        if code not in ok:
            raise SystemExit(f"failed ({code}): {' '.join(cmd)}")
        runs.append((wall, mb))
    return min(r[0] for r in runs), max(r[1] for r in runs)


def pycan_iterate(path: Path, repeat: int) -> float:
    code = "import can,sys\nfor m in can.LogReader(sys.argv[1]): pass\n"
    return best([sys.executable, "-c", code, str(path)], repeat)[0]


def has_check() -> bool:
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", "--help"],
        capture_output=True,
        cwd=ROOT,
        check=False,
    )
    return out.returncode == 0


def ensure(n: int, suffixes: list[str]) -> Path:
    stem = OUT / f"bench_{n}"
    missing = [s for s in suffixes if not stem.with_suffix(s).exists()]
    if missing:
        print(f"generating {n} frames: {','.join(missing)} ...", file=sys.stderr)
        subprocess.run(
            [sys.executable, str(HERE / "generate.py"), str(n), str(stem), ",".join(missing)],
            check=True,
        )
    return stem


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--sizes", default="1e6", help="frame counts, comma separated (first: formats and text)"
    )
    ap.add_argument(
        "--formats", default=".log,.asc,.blf", help="log formats for the throughput runs"
    )
    ap.add_argument("--repeat", type=int, default=3, help="runs per measurement, best kept")
    args = ap.parse_args(argv)
    sizes = [int(float(x)) for x in args.sizes.split(",")]
    formats = args.formats.split(",")
    n = sizes[0]
    stem = ensure(n, formats)
    cli = [sys.executable, "-m", "cananalyze"]
    results = []
    for suffix in formats:
        path = stem.with_suffix(suffix)
        summ_s, summ_mb = best(cli + ["decode", str(path), "--summary"], args.repeat)
        pc_s = pycan_iterate(path, max(1, args.repeat - 1))
        results.append((suffix, summ_s, summ_mb, pc_s))
    with tempfile.TemporaryDirectory() as tmp:
        text_path = stem.with_suffix(formats[0])
        text_s, text_mb = best(
            cli + ["decode", str(text_path), "-o", str(Path(tmp) / "out.txt")], args.repeat
        )
        lines = sum(1 for _ in open(Path(tmp) / "out.txt", "rb"))
    check = None
    if has_check():
        check_s, _ = best(
            cli + ["check", str(stem.with_suffix(formats[0]))], args.repeat, ok=(0, 1)
        )
        check = check_s / results[0][1]
    rss = []
    for size in sizes:
        s = ensure(size, [".log"]).with_suffix(".log")
        wall, mb = best(cli + ["decode", str(s), "--summary"], 1)
        rss.append((size, wall, mb))
    help_s, _ = best(cli + ["--help"], max(5, args.repeat))

    print(f"{n} frames, {os.cpu_count()} cores, best of {args.repeat}")
    print("ratio python-can LogReader / cananalyze decode --summary (target >= 20x):")
    for suffix, summ_s, _, pc_s in results:
        print(f"  {suffix:5} {pc_s / summ_s:6.1f}x")
    print("decode --summary, whole process:")
    for suffix, summ_s, summ_mb, pc_s in results:
        rate = n / summ_s
        mark = (
            "ok" if rate >= TARGETS.get(suffix, 0) else f"below {TARGETS.get(suffix, 0) / 1e6:g}M"
        )
        print(
            f"  {suffix:5} {rate / 1e6:6.2f}M frames/s {summ_s:6.2f} s {summ_mb:5.0f} MB"
            f"   python-can {n / pc_s / 1e3:5.0f}k frames/s {pc_s:6.2f} s   [{mark}]"
        )
    print(
        f"text output ({formats[0]} -> file): {lines / text_s / 1e6:.2f}M lines/s, {text_s:.2f} s, {text_mb:.0f} MB"
    )
    if check is None:
        print("check overhead: skipped (no `cananalyze check` in this build)")
    else:
        print(f"check overhead: {check:.2f}x the time of decode --summary")
    print("peak RSS, decode --summary on candump (target <= 600 MB at 10M, flat):")
    for size, wall, mb in rss:
        print(f"  {size / 1e6:6g}M frames  {mb:6.0f} MB  {size / wall / 1e6:5.2f}M frames/s")
    print(f"cananalyze --help: {help_s:.3f} s (target < 0.3 s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
