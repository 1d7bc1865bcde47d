"""Decode throughput and peak memory, side by side with python-can's LogReader.

For each format: the whole `cananalyze decode FILE --summary` process (frames
classified, SDO reassembled, summary) and `decode FILE -o /dev/null` (full text
output), each in a fresh process with its peak RSS, and plain iteration of
python-can's `can.LogReader` over the same file in the same run. Ratios first.

    python benchmarks/bench_decode.py [N_FRAMES] [FORMATS]   # default 1e6 .log,.asc,.blf
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
OUT = HERE / "out"


def run_process(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and peak RSS (MB) of a child process."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {' '.join(cmd)}")
    return wall, usage.ru_maxrss / 1024


def pycan_iterate(path: Path) -> tuple[float, int]:
    code = (
        "import can,sys,time;t=time.perf_counter();n=0\n"
        "for m in can.LogReader(sys.argv[1]): n+=1\n"
        "print(n, time.perf_counter()-t)"
    )
    t = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, check=True)
    wall = time.perf_counter() - t
    return wall, int(out.stdout.split()[0])


def main(argv: list[str]) -> int:
    n = int(float(argv[0])) if argv else 1_000_000
    formats = argv[1].split(",") if len(argv) > 1 else [".log", ".asc", ".blf"]
    stem = OUT / f"bench_{n}"
    missing = [s for s in formats if not stem.with_suffix(s).exists()]
    if missing:
        subprocess.run([sys.executable, str(HERE / "generate.py"), str(n), str(stem), ",".join(missing)], check=True)
    rows = []
    for suffix in formats:
        path = stem.with_suffix(suffix)
        base = [sys.executable, "-m", "cananalyze", "decode", str(path)]
        summ_s, summ_mb = run_process(base + ["--summary"])
        text_s, text_mb = run_process(base + ["-o", os.devnull])
        pc_s, pc_n = pycan_iterate(path)
        rows.append((suffix, summ_s, summ_mb, text_s, text_mb, pc_s, pc_n))
    print(f"{n} frames, {os.cpu_count()} cores")
    print("ratio (python-can LogReader time / cananalyze decode --summary time):")
    for suffix, summ_s, _, _, _, pc_s, _ in rows:
        print(f"  {suffix:5} {pc_s / summ_s:6.1f}x")
    print(f"{'format':6} {'decode --summary':>24} {'decode text output':>26} {'python-can iterate':>22}")
    for suffix, summ_s, summ_mb, text_s, text_mb, pc_s, pc_n in rows:
        print(
            f"{suffix:6} {n / summ_s / 1e6:6.2f}M fr/s {summ_s:5.2f}s {summ_mb:5.0f}MB"
            f" {n / text_s / 1e6:6.2f}M lines/s {text_s:5.2f}s {text_mb:5.0f}MB"
            f" {pc_n / pc_s / 1e3:6.0f}k fr/s {pc_s:6.2f}s"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
