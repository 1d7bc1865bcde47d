"""The CPU an export spends in libraries alone, against what 20x python-can allows.

    python benchmarks/bench_floor.py                 # 10M-frame logs (~3 min)
    python benchmarks/bench_floor.py --size 1e6      # quicker

Issue 10 asks `export --parquet` to run 20x faster than python-can's `LogReader`
iterates the same file. Part of every export is not ours to speed up: reading
the input (isal's inflate for BLF, the line parsers' passes), Arrow encoding
the finished tables as Parquet, and starting Python with its imports. This
measures those alone, in CPU seconds: the input read batch by batch, and the
exported tables re-encoded with the writers' own options. On two cores an
export can never take less wall time than half of that CPU, whatever the
decoding costs, which is what the last column compares with the 20x budget.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_decode import CLI, DEVICES, ENV, PyCanRun, ensure  # noqa: E402

READ = """
import sys, time
from cananalyze.runtime import allocator
allocator.tune()  # as the CLI runs
from cananalyze.formats.source import open_log
c = time.process_time()
for _ in open_log(sys.argv[1]).batches():
    pass
print(time.process_time() - c)
"""
IMPORTS = (
    "import cananalyze.cli.main, cananalyze.cli.export, cananalyze.outputs.tables.stream, "
    "pyarrow.parquet"
)


def read_cpu(path: Path, repeat: int) -> float:
    """CPU seconds of reading the log into frame batches (no decoding), best of `repeat`."""
    return min(float(_run([sys.executable, "-c", READ, str(path)])) for _ in range(repeat))


def encode_cpu(tables: Path, repeat: int) -> dict[str, float]:
    """CPU seconds Arrow takes to write each exported table again, with the stream
    writer's options (row groups as the export cut them)."""
    import pyarrow.parquet as pq

    from cananalyze.outputs.tables.stream import EVENTS, FRAMES, SIGNALS

    specs = {"frames": FRAMES, "signals": SIGNALS, "events": EVENTS, "sdo": None}
    out = {}
    for name, spec in specs.items():
        source = pq.ParquetFile(tables / f"{name}.parquet")
        groups = [source.read_row_group(i) for i in range(source.num_row_groups)]
        options = spec.parquet_options() if spec is not None else {}
        best = float("inf")
        for _ in range(repeat):
            c = time.process_time()
            with pq.ParquetWriter(
                tables / "again.parquet", source.schema_arrow, compression="snappy", **options
            ) as writer:
                for group in groups:
                    writer.write_table(group)
            best = min(best, time.process_time() - c)
        out[name] = best
    return out


def startup_cpu(repeat: int) -> float:
    """CPU seconds of starting Python and importing what an export imports."""
    best = float("inf")
    for _ in range(repeat):
        proc = subprocess.Popen([sys.executable, "-c", IMPORTS], env=ENV)
        _, _, usage = os.wait4(proc.pid, 0)
        best = min(best, usage.ru_utime + usage.ru_stime)
    return best


def _run(cmd: list[str]) -> str:
    """The command's output; its own error message (not a traceback) when it fails."""
    done = subprocess.run(cmd, capture_output=True, text=True, env=ENV)
    if done.returncode != 0:
        raise SystemExit(f"failed ({done.returncode}): {' '.join(cmd)}\n{done.stderr.strip()}")
    return done.stdout


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=float, default=10e6, help="frames per log (default 10e6)")
    ap.add_argument("--formats", default=".log,.blf,.asc")
    ap.add_argument("--repeat", type=int, default=3, help="runs per figure, best kept")
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where logs are generated")
    args = ap.parse_args(argv)
    n = int(args.size)
    formats = args.formats.split(",")
    if not set(formats) <= {".log", ".blf", ".asc"}:
        ap.error(f"--formats: .log, .blf or .asc, not {args.formats}")
    args.out.mkdir(parents=True, exist_ok=True)
    stem = ensure(args.out, n, formats, [])
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        tables = Path(tmp) / "pq"
        log = str(stem.with_suffix(formats[0]))
        print(f"exporting {log} once for its tables ...", flush=True)
        _run(CLI + ["export", log, "--parquet", str(tables), *DEVICES, "-q"])
        encode = encode_cpu(tables, args.repeat)
        shutil.rmtree(tables)
    start = startup_cpu(max(3, args.repeat))
    written = sum(encode.values())
    print()
    print(f"{n:,}-frame logs, CPU seconds (best of {args.repeat}), 2 cores")
    parts = ", ".join(f"{k} {v:.2f}" for k, v in encode.items())
    print(f"  Parquet encoding of the exported tables: {written:.2f} s ({parts})")
    print(f"  interpreter and imports: {start:.2f} s")
    print(
        f"{'format':<7} {'read':>6} {'library CPU':>12} {'floor (wall)':>13} "
        f"{'python-can':>11} {'20x needs':>10}"
    )
    for suffix in formats:
        path = stem.with_suffix(suffix)
        read = read_cpu(path, args.repeat)
        pycan = PyCanRun(path, n, min(n, 1_000_000))
        for _ in range(max(1, args.repeat - 1)):
            pycan.once()
        total = read + written + start
        print(
            f"{suffix:<7} {read:6.2f} {total:12.2f} {total / 2:12.2f}s "
            f"{pycan.wall:10.1f}s {pycan.wall / 20:9.2f}s"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
