"""The CPU an export spends in libraries alone, beside the export's and python-can's CPU.

    python benchmarks/bench_floor.py                 # 10M-frame logs (~10 min)
    python benchmarks/bench_floor.py --size 1e6      # quicker

Part of every export is not ours to speed up: reading the input (isal's inflate
for BLF, the line parsers' passes), Arrow encoding the finished tables as
Parquet, and starting Python with its imports. This measures those alone, in CPU
seconds (user + system): the input read batch by batch, and the exported tables
re-encoded with the writers' own options; their sum is the floor. Beside it, per
format and in the same rounds, the CPU of `export --parquet` (16 devices, as
bench_decode's) and of python-can's `LogReader` iterating the whole file, each a
fresh process (`--pycan-prefix N`: python-can on the first N frames, its loop's CPU
scaled). Each is judged against the current targets (bench_decode's): the export at
most 1.25x its floor, python-can's CPU at least 12x the export's on candump, 15x on
ASC, 8x on BLF.
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

from bench_decode import (  # noqa: E402
    CLI,
    DEVICES,
    ENV,
    FLOOR_TARGET,
    RATIO_TARGET,
    PyCanRun,
    Run,
    _remove,
    ensure,
    mark,
    rounds,
)

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
    ap.add_argument(
        "--pycan-prefix",
        type=float,
        default=0,
        help="python-can on the first N frames, its CPU scaled (default 0: the whole file)",
    )
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where logs are generated")
    args = ap.parse_args(argv)
    n = int(args.size)
    formats = args.formats.split(",")
    if not set(formats) <= {".log", ".blf", ".asc"}:
        ap.error(f"--formats: .log, .blf or .asc, not {args.formats}")
    args.out.mkdir(parents=True, exist_ok=True)
    stem = ensure(args.out, n, formats, [])
    rows = []
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        tables = Path(tmp) / "pq"
        log = str(stem.with_suffix(formats[0]))
        print(f"exporting {log} once for its tables ...", flush=True)
        _run(CLI + ["export", log, "--parquet", str(tables), *DEVICES, "-q"])
        encode = encode_cpu(tables, args.repeat)
        shutil.rmtree(tables)
        start = startup_cpu(max(3, args.repeat))
        written = sum(encode.values())
        for suffix in formats:
            path = stem.with_suffix(suffix)
            print(f"measuring {suffix}: read, export --parquet, python-can ...", flush=True)
            read = read_cpu(path, args.repeat)
            cmd = CLI + ["export", str(path), "--parquet", str(tables), *DEVICES, "-q"]
            export = Run(cmd, after=_remove(tables))
            pycan = PyCanRun(path, n, int(args.pycan_prefix))
            rounds([export, pycan], args.repeat)
            rows.append((suffix, read, read + written + start, export, pycan))
    print()
    hows = "; ".join(sorted({p.how for *_, p in rows}))
    print(
        f"{n:,}-frame logs, CPU seconds (user + system, best of {args.repeat}); python-can: {hows}"
    )
    parts = ", ".join(f"{k} {v:.2f}" for k, v in encode.items())
    print(f"  Parquet encoding of the exported tables: {written:.2f} s ({parts})")
    print(f"  interpreter and imports: {start:.2f} s")
    print(
        f"{'format':<7} {'read':>6} {'floor':>7} {'export':>7}  {'export/floor':<20} "
        f"{'python-can':>10}  python-can/export"
    )
    for suffix, read, floor, export, pycan in rows:
        over, ahead, target = export.cpu / floor, pycan.cpu / export.cpu, RATIO_TARGET[suffix]
        verdict = f"{over:5.2f}x <= {FLOOR_TARGET:g}x {mark(over <= FLOOR_TARGET)}"
        print(
            f"{suffix:<7} {read:6.2f} {floor:7.2f} {export.cpu:7.2f}  {verdict:<20} "
            f"{pycan.cpu:10.2f}  {ahead:5.1f}x >= {target:g}x {mark(ahead >= target)}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
