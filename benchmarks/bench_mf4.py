"""The MF4 reader's speed against the candump and BLF readers on the same traffic.

    python benchmarks/bench_mf4.py                # 1M frames, 3 rounds
    python benchmarks/bench_mf4.py 5e6 --rounds 5
    python benchmarks/bench_mf4.py 1e6 --pycan    # and python-can's MF4Reader (slow)

The traffic is benchmarks/generate.py's (16 CANopen nodes); candump and BLF are
written as bench_decode.py writes them, MF4 by asammdf in CANedge's layout (one
CAN_DataFrame group, BusChannel, 64-byte DataBytes), once plain and once with
deflate-compressed data blocks (`compression=1`). Each figure is a fresh process
reading every batch of the log and nothing else (bench_decode.py's "reader alone"),
timed with wait4: CPU seconds (user + system) and wall seconds, the median of the
rounds, and frames per CPU second and per wall second. Interpreter start and imports
are inside every figure (asammdf's import is ~0.4 s of the MF4 ones).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
from generate import START, generate, log_stem  # noqa: E402

sys.path.insert(0, str(ROOT))
from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR  # noqa: E402
from cananalyze.formats.logfile import write_log  # noqa: E402

READER = """
import sys
from cananalyze.formats.source import open_log
src = open_log(sys.argv[1])
print(sum(len(b) for b in src.batches()))
"""
PYCAN = """
import sys
import can
print(sum(1 for _ in can.MF4Reader(sys.argv[1])))
"""
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def write_mf4(batch, path: Path, compression: int) -> None:
    """The batch's data frames as one CAN_DataFrame group, built as columns."""
    import asammdf

    keep = (batch.flags & (FLAG_RTR | FLAG_ERR)) == 0
    n = int(keep.sum())
    kind = "CAN_DataFrame"
    s = np.zeros(
        n,
        [
            (f"{kind}.BusChannel", "u1"),
            (f"{kind}.ID", "<u4"),
            (f"{kind}.IDE", "u1"),
            (f"{kind}.DLC", "u1"),
            (f"{kind}.DataLength", "u1"),
            (f"{kind}.DataBytes", "u1", (64,)),
            (f"{kind}.Dir", "u1"),
            (f"{kind}.EDL", "u1"),
            (f"{kind}.BRS", "u1"),
            (f"{kind}.ESI", "u1"),
        ],
    )
    s[f"{kind}.BusChannel"] = batch.channel[keep] + 1
    s[f"{kind}.ID"] = batch.can_id[keep]
    s[f"{kind}.IDE"] = (batch.flags[keep] & FLAG_EXT) != 0
    s[f"{kind}.DLC"] = batch.dlc[keep]
    s[f"{kind}.DataLength"] = batch.dlc[keep]
    s[f"{kind}.DataBytes"][:, :8] = batch.data[keep]
    mdf = asammdf.MDF(version="4.10")
    mdf.header.start_time = datetime.fromtimestamp(START, UTC)
    src = asammdf.Source(
        name="CAN",
        path="CAN",
        comment="",
        source_type=asammdf.Source.SOURCE_BUS,
        bus_type=asammdf.Source.BUS_TYPE_CAN,
    )
    mdf.append(asammdf.Signal(s, batch.t[keep] - START, name=kind, source=src), acq_name="CAN")
    mdf.save(path, overwrite=True, compression=compression)
    mdf.close()


def logs(n: int, out: Path) -> dict[str, Path]:
    """The n-frame logs, written once and kept in `out` for the next run."""
    stem = log_stem(out, n)
    paths = {
        "candump": stem.with_suffix(".log"),
        "blf": stem.with_suffix(".blf"),
        "mf4": stem.with_suffix(".mf4"),
        "mf4 deflate": stem.parent / f"{stem.name}_dz.mf4",
    }
    if all(p.exists() for p in paths.values()):
        return paths
    out.mkdir(parents=True, exist_ok=True)
    batch = generate(n)
    for name, p in paths.items():
        if p.exists():
            continue
        if name.startswith("mf4"):
            write_mf4(batch, p, compression=1 if "deflate" in name else 0)
        else:
            write_log(batch, p)
        print(f"wrote {p} ({p.stat().st_size / 1e6:.0f} MB)", file=sys.stderr)
    return paths


def once(code: str, path: Path) -> tuple[float, float, int]:
    """(CPU seconds, wall seconds, frames) of one fresh process."""
    t = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-c", code, str(path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        cwd=ROOT,
        env=dict(ENV, PYTHONPATH=str(ROOT)),
    )
    printed = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"failed: {path}")
    return usage.ru_utime + usage.ru_stime, wall, int(printed)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames", nargs="?", default="1e6")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=HERE / "out")
    ap.add_argument("--pycan", action="store_true", help="python-can's MF4Reader too")
    args = ap.parse_args()
    n = int(float(args.frames))
    paths = logs(n, args.out)
    rows = [(name, READER, p) for name, p in paths.items()]
    if args.pycan:
        rows.append(("python-can MF4Reader", PYCAN, paths["mf4"]))
    figures: dict[str, list[tuple[float, float, int]]] = {name: [] for name, _, _ in rows}
    for _ in range(args.rounds):  # every format once a round: the machine's load is shared
        for name, code, p in rows:
            figures[name].append(once(code, p))
    print(f"{n:,} frames generated, median of {args.rounds} rounds, reader alone")
    print(
        f"{'log':22} {'MB':>6} {'frames':>10} {'CPU s':>7} {'wall s':>7} {'frames/CPU s':>13} {'frames/wall s':>14}"
    )
    for name, _, p in rows:
        cpu = statistics.median(f[0] for f in figures[name])
        wall = statistics.median(f[1] for f in figures[name])
        frames = figures[name][0][2]
        mb = p.stat().st_size / 1e6
        print(
            f"{name:22} {mb:6.0f} {frames:10,} {cpu:7.2f} {wall:7.2f} "
            f"{frames / cpu:13,.0f} {frames / wall:14,.0f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
