"""`export --parquet` whole-process cost: the streaming writer vs the Capture path, same log.

Each run is a fresh process (imports, peak memory and all), 16 DAT 7014 nodes so
every TPDO is decoded into signals. Prints frames/s, wall and CPU seconds (CPU is
the fairer figure on a shared machine) and peak RSS. The Capture path is
`run_pipeline` + `parquet_out.write_parquet`, what `export --parquet` did before
it streamed (and still does when --mcap/--rrd are asked for too).

    python benchmarks/bench_export_stream.py LOG [LOG ...]    # e.g. benchmarks/out/bench_1000000.log
    python benchmarks/bench_export_stream.py --stream-only LOG --compression zstd
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEVICES = [f"--device={k}=dat7014" for k in range(1, 17)]

CAPTURE = """
import sys, argparse
from cananalyze.capture import run_pipeline
from cananalyze.outputs.tables.whole import write_parquet
args = argparse.Namespace(log=sys.argv[1], network=None, eds=None,
    device=[f"{k}=dat7014" for k in range(1, 17)], strict=False, input_format=None,
    sdo_timeout=1.0)
cap = run_pipeline(args)
write_parquet(cap, sys.argv[2], sys.argv[3])
print(len(cap))
"""


def run(cmd: list[str]) -> tuple[float, float, int]:
    """(wall s, CPU s, peak RSS MB) of one child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, after.ru_maxrss // 1024  # maxrss of the largest child so far


def frames_in(log: Path) -> int:
    from cananalyze.io.source import open_log

    return sum(len(b) for b in open_log(str(log)).batches())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("logs", nargs="+", type=Path)
    p.add_argument("--compression", default="zstd")
    p.add_argument("--stream-only", action="store_true", help="skip the Capture path")
    opts = p.parse_args()
    sys.path.insert(0, str(ROOT))
    with tempfile.TemporaryDirectory() as tmp:
        for log in opts.logs:
            n = frames_in(log)
            print(f"{log} ({n:,} frames, {os.path.getsize(log) >> 20} MB)")
            stream = [sys.executable, "-m", "cananalyze", "export", str(log)]
            stream += ["--parquet", f"{tmp}/s", "--parquet-compression", opts.compression, "-q"]
            rows = [("stream", stream + DEVICES)]
            if not opts.stream_only:
                capture = [sys.executable, "-c", CAPTURE, str(log), f"{tmp}/c", opts.compression]
                rows.append(("capture", capture))
            for label, cmd in rows:
                wall, cpu, rss = run(cmd)
                print(
                    f"  {label:<8} {n / wall / 1e6:5.2f} M frames/s wall  "
                    f"{n / cpu / 1e6:5.2f} M/s per CPU-s   wall {wall:6.2f} s  "
                    f"cpu {cpu:6.2f} s  peak RSS <= {rss} MB",
                    flush=True,
                )


if __name__ == "__main__":
    main()
