"""Every performance figure of issue 10 in one command, ratios first.

    python benchmarks/bench_decode.py                 # the issue's 10M-frame logs (~10 min)
    python benchmarks/bench_decode.py --quick         # 1M frames (~2 min)
    python benchmarks/bench_decode.py --flat 50e6     # flatness 5M vs 50M (a 2.1 GB candump)

Each figure is a fresh `python -m cananalyze ...` process (whole-process wall
time, CPU time and peak RSS from wait4), the best of `--repeat` runs: other work
on the machine only ever makes a run slower. Figures that are compared run in
rounds, one after the other in each round (per format: export, decode --summary
and python-can's `LogReader` iterating the same file; on the first, check too),
so the ratios and check's overhead hardly depend on the machine's load.
The headline command is the issue's "decoded tables written as Parquet":
`cananalyze export LOG --parquet DIR --device N=dat7014 (N=1..16) -q`, so PDOs
are decoded into signals. Logs come from benchmarks/generate.py and are kept
in --out (default benchmarks/out, git-ignored) for the next run; --clean
deletes the ones this run generated.
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
ROOT = HERE.parent
FRAMES_TARGET = {".log": 3e6, ".asc": 2e6, ".blf": 3e6}
DEVICES = [arg for k in range(1, 17) for arg in ("--device", f"{k}=dat7014")]
CLI = [sys.executable, "-m", "cananalyze"]
# Measured as installed: bytecode cached. With PYTHONDONTWRITEBYTECODE set (some CI images
# and this machine set it) every process would recompile every module, ~0.2 s each.
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
PYCAN = """
import itertools, sys, time
t0 = time.perf_counter()
import can
reader = can.LogReader(sys.argv[1])
t1 = time.perf_counter()
limit = int(sys.argv[2])
n = 0
for _ in (itertools.islice(reader, limit) if limit else reader):
    n += 1
print(t1 - t0, time.perf_counter() - t1, n)
"""


class Run:
    """Best wall and CPU seconds, highest peak RSS (MB) of repeated runs of one command."""

    def __init__(self, cmd: list[str], ok: tuple[int, ...] = (0,)) -> None:
        self.cmd, self.ok = cmd, ok
        self.wall = self.cpu = float("inf")
        self.mb = 0.0

    def once(self) -> None:
        t = time.perf_counter()
        proc = subprocess.Popen(
            self.cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, env=ENV
        )
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        if os.waitstatus_to_exitcode(status) not in self.ok:
            code = os.waitstatus_to_exitcode(status)
            raise SystemExit(f"failed ({code}): {' '.join(self.cmd)}")
        self.wall = min(self.wall, wall)
        self.cpu = min(self.cpu, usage.ru_utime + usage.ru_stime)
        self.mb = max(self.mb, usage.ru_maxrss / 1024)


def rounds(runs: list, repeat: int) -> None:
    """Each run once per round, `repeat` rounds: figures that are compared (a ratio, an
    overhead) are measured side by side, so a change in the machine's load between
    them cannot pass for a difference (this machine's speed drifts by a third)."""
    for _ in range(repeat):
        for run in runs:
            run.once()


def measured(cmd: list[str], repeat: int, ok: tuple[int, ...] = (0,)) -> Run:
    run = Run(cmd, ok)
    rounds([run], repeat)
    return run


def ensure(out: Path, n: int, suffixes: list[str], made: list[Path]) -> Path:
    """The generator's n-frame logs, generated when missing (the time it took is printed)."""
    stem = out / f"bench_{n}"
    missing = [s for s in suffixes if not stem.with_suffix(s).exists()]
    if missing:
        t = time.perf_counter()
        print(f"generating {n:,} frames as {','.join(missing)} in {out} ...", flush=True)
        subprocess.run(
            [sys.executable, str(HERE / "generate.py"), str(n), str(stem), ",".join(missing)],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        made += [stem.with_suffix(s) for s in missing]
        print(f"  took {time.perf_counter() - t:.1f} s", flush=True)
    return stem


class PyCanRun:
    """python-can LogReader's whole-process time over the file; scaled from a prefix if asked."""

    def __init__(self, path: Path, n: int, prefix: int) -> None:
        self.path, self.n = path, n
        self.limit = prefix if 0 < prefix < n else 0
        self.wall = float("inf")
        lim = self.limit
        self.how = f"first {lim / 1e6:g}M frames, scaled x{n / lim:g}" if lim else "whole file"

    def once(self) -> None:
        t = time.perf_counter()
        out = subprocess.run(
            [sys.executable, "-c", PYCAN, str(self.path), str(self.limit)],
            capture_output=True,
            text=True,
            check=True,
        )
        wall = time.perf_counter() - t
        setup, loop, count = out.stdout.split()
        if self.limit:  # start-up as measured, the loop scaled to the whole file
            wall = wall - float(loop) + float(loop) * self.n / int(count)
        self.wall = min(self.wall, wall)


def mark(ok: bool) -> str:
    return "ok" if ok else "BELOW"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=float, default=10e6, help="frames per log (default 10e6)")
    ap.add_argument("--quick", action="store_true", help="1M-frame logs (a few minutes)")
    ap.add_argument("--formats", default=".log,.asc,.blf", help="log formats (default all three)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per figure, best kept")
    ap.add_argument(
        "--pycan-prefix",
        type=float,
        default=1e6,
        help="time python-can on the first N frames and scale (0: whole file; default 1e6)",
    )
    ap.add_argument(
        "--flat",
        type=float,
        default=0,
        help="also peak RSS at this size (e.g. 50e6, a 2.1 GB candump) vs 5M",
    )
    ap.add_argument("--out", type=Path, default=HERE / "out", help="where logs are generated")
    ap.add_argument("--clean", action="store_true", help="delete the logs this run generated")
    args = ap.parse_args(argv)
    n = int(1e6 if args.quick else args.size)
    formats = args.formats.split(",")
    args.out.mkdir(parents=True, exist_ok=True)
    made: list[Path] = []
    load0 = os.getloadavg()
    try:
        rows = measure(args, n, formats, made)
    finally:
        if args.clean:
            for p in made:
                p.unlink(missing_ok=True)
    load1 = os.getloadavg()
    print()
    print(
        f"machine: {os.cpu_count()} cores, load average {load0[0]:.2f} before, "
        f"{load1[0]:.2f} after; best of {args.repeat}; {n:,}-frame logs"
    )
    width = max(len(r[0]) for r in rows)
    for name, value, target, verdict in rows:
        print(f"{name:<{width}}  {value:<48} {target:<14} {verdict}")
    return 0


def measure(args, n: int, formats: list[str], made: list[Path]) -> list[tuple[str, str, str, str]]:
    stem = ensure(args.out, n, formats, made)
    rows: list[tuple[str, str, str, str]] = []
    per_format = {}
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        pq = Path(tmp) / "pq"
        for k, suffix in enumerate(formats):
            log = str(stem.with_suffix(suffix))
            what = "export --parquet, decode --summary, python-can LogReader"
            export = Run(CLI + ["export", log, "--parquet", str(pq), *DEVICES, "-q"])
            summary = Run(CLI + ["decode", log, "--summary", *DEVICES])
            runs = [export, summary, PyCanRun(stem.with_suffix(suffix), n, int(args.pycan_prefix))]
            if k == 0:  # check's overhead over the same decode, in the same rounds
                check = Run(CLI + ["check", log, *DEVICES], ok=(0, 1))
                runs.append(check)
                what += ", check"
            print(f"{suffix}: {what}, in {args.repeat} rounds ...", flush=True)
            rounds(runs, args.repeat)
            shutil.rmtree(pq, ignore_errors=True)
            per_format[suffix] = (export, summary, runs[2].wall, runs[2].how)
        log = str(stem.with_suffix(formats[0]))
        base = per_format[formats[0]][1]
        print("text output ...", flush=True)
        text_runs = []
        for devices, fmt in (([], "text"), (DEVICES, "text"), ([], "jsonl")):
            dest = Path(tmp) / "out.txt"
            cmd = CLI + ["decode", log, *devices, "--format", fmt, "-o", str(dest)]
            run = measured(cmd, args.repeat if fmt == "text" else 1)
            with open(dest, "rb") as f:
                lines = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 24), b""))
            dest.unlink()
            what = ("16 devices" if devices else "no devices") + (
                "" if fmt == "text" else ", jsonl"
            )
            text_runs.append((run, lines, what))
        # the timeline exports stream too: their peak at this size and at 5M
        timelines = []
        for kind, dest in (("mcap", Path(tmp) / "t.mcap"), ("rrd", Path(tmp) / "t.rrd")):
            print(f"export --{kind} ...", flush=True)
            sizes = [n] + ([int(5e6)] if n > 5e6 else [])
            got = []
            for size in sizes:
                s = ensure(args.out, size, [".log"], made).with_suffix(".log")
                got.append(
                    measured(CLI + ["export", str(s), f"--{kind}", str(dest), *DEVICES, "-q"], 1)
                )
                dest.unlink(missing_ok=True)
            timelines.append((kind, got))
        flat = []
        big = int(args.flat) or (n if n > 5e6 else 0)
        if big:
            for size in (int(5e6), big):
                s = ensure(args.out, size, [".log"], made).with_suffix(".log")
                print(f"peak RSS at {size / 1e6:g}M ...", flush=True)
                run = measured(CLI + ["export", str(s), "--parquet", str(pq), *DEVICES, "-q"], 1)
                shutil.rmtree(pq, ignore_errors=True)
                flat.append((size, run))
        help_run = measured(CLI + ["--help"], max(5, args.repeat))

    # 1. ratios first
    for suffix, (export, _, pc, _) in per_format.items():
        rows.append(
            (
                f"python-can LogReader / export --parquet {suffix}",
                f"{pc / export.wall:5.1f}x  ({pc:.1f} s / {export.wall:.2f} s)",
                ">= 20x",
                mark(pc / export.wall >= 20),
            )
        )
    for suffix, (_, summary, pc, _) in per_format.items():
        rows.append(
            (
                f"python-can LogReader / decode --summary {suffix}",
                f"{pc / summary.wall:5.1f}x  (reference)",
                "",
                "",
            )
        )
    hows = sorted({v[3] for v in per_format.values()})
    rows.append(("  python-can timed on", "; ".join(hows), "", ""))
    # 2. frames/s
    for suffix, (export, summary, _, _) in per_format.items():
        target = FRAMES_TARGET.get(suffix, 0)
        rate = n / export.wall
        rows.append(
            (
                f"export --parquet {suffix} frames/s",
                f"{rate / 1e6:5.2f}M  ({export.wall:.2f} s, cpu {export.cpu:.2f} s, "
                f"{export.mb:.0f} MB)",
                f">= {target / 1e6:g}M",
                mark(rate >= target),
            )
        )
        rows.append(
            (
                f"decode --summary {suffix} frames/s",
                f"{n / summary.wall / 1e6:5.2f}M  ({summary.wall:.2f} s, cpu {summary.cpu:.2f} s)",
                "(reference)",
                "",
            )
        )
    # 3. check overhead: both read and decode the same log with the same devices and
    # both run the timing analysis; check adds the rules (and prints findings)
    over_cpu = check.cpu / base.cpu - 1
    over_wall = check.wall / base.wall - 1
    rows.append(
        (
            f"check vs decode --summary ({formats[0]}), cpu",
            f"{100 * over_cpu:+5.1f} %  ({check.cpu:.2f} s vs {base.cpu:.2f} s)",
            "<= +25 %",
            mark(over_cpu <= 0.25),
        )
    )
    rows.append(
        (
            f"check vs decode --summary ({formats[0]}), wall",
            f"{100 * over_wall:+5.1f} %  ({check.wall:.2f} s vs {base.wall:.2f} s)",
            "<= +25 %",
            mark(over_wall <= 0.25),
        )
    )
    # 4. text output
    for run, lines, what in text_runs:  # JSONL: a reference figure, best of one run
        rate = lines / run.wall
        text = "jsonl" not in what
        rows.append(
            (
                f"decode -o FILE ({formats[0]}, {what}) lines/s",
                f"{rate / 1e6:5.2f}M  ({lines:,} lines, {run.wall:.2f} s, cpu {run.cpu:.2f} s)",
                ">= 1M" if text else "(reference)",
                mark(rate >= 1e6) if text else "",
            )
        )
    for kind, got in timelines:  # reference figures: one run each
        run = got[0]
        at5 = f"; {got[1].mb:.0f} MB at 5M" if len(got) > 1 else ""
        rows.append(
            (
                f"export --{kind} (.log, 16 devices) frames/s",
                f"{n / run.wall / 1e6:5.2f}M  ({run.wall:.2f} s, cpu {run.cpu:.2f} s, "
                f"{run.mb:.0f} MB{at5})",
                "(reference)",
                "",
            )
        )
    # 5. memory
    peak = max(v[0].mb for v in per_format.values())
    rows.append(
        (
            f"peak RSS export --parquet at {n / 1e6:g}M",
            f"{peak:.0f} MB",
            "<= 600 MB" if n >= 10e6 else "(600 MB at 10M)",
            mark(peak <= 600) if n >= 10e6 else "",
        )
    )
    if flat:
        (s5, r5), (sb, rb) = flat
        ratio = rb.mb / r5.mb - 1
        more = "" if args.flat else "; 50M: --flat 50e6"
        rows.append(
            (
                f"peak RSS {sb / 1e6:g}M vs {s5 / 1e6:g}M (.log{more})",
                f"{100 * ratio:+5.1f} %  ({rb.mb:.0f} MB vs {r5.mb:.0f} MB)",
                "within 10 %",
                mark(abs(ratio) <= 0.10),
            )
        )
    else:
        rows.append(
            ("peak RSS flatness", "not measured: --flat 50e6 (5M vs 50M)", "within 10 %", "")
        )
    # 6. start-up
    rows.append(
        (
            "cananalyze --help",
            f"{help_run.wall:.3f} s",
            "< 0.3 s",
            mark(help_run.wall < 0.3),
        )
    )
    return rows


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
