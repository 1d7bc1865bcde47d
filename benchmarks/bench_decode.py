"""Every performance figure of issues 23 and 43 in one command: CPU ratios, then wall.

    python benchmarks/bench_decode.py                 # the issue's 10M-frame logs (~15 min)
    python benchmarks/bench_decode.py --quick         # 1M frames (~3 min)
    python benchmarks/bench_decode.py --flat 50e6     # flatness 5M vs 50M (a 2.1 GB candump)
    python benchmarks/bench_decode.py --quick --against ../baseline   # this tree vs another

Each figure is a fresh process (whole-process wall time, CPU time (user + system)
and peak RSS from wait4), the best of `--repeat` runs: other work on the machine
only ever makes a run slower. CPU seconds are the steady figure on a shared
machine (wall time swings by a third with its load), so the targets are CPU
ratios, and every ratio's two sides run in the same rounds, one after the other
(per format: export, decode --summary, the reader alone, python-can's `LogReader`
iterating the same file, canopen-lens's C++ core on the candump log, its user and
system CPU apart beside the export's; on the first, check too, which must exit 0:
the generator's bus is healthy). The checks' cost where they find something is
measured on the generator's faulty bus (`--faults`): check over decode --summary on
that log. Wall figures follow, each with the 1-minute load average when its
best run started. The headline command is the issue's "decoded tables written as
Parquet": `cananalyze export LOG --parquet DIR --device N=dat7014 (N=1..16) -q`, so
PDOs are decoded into signals. canopen-lens (`pip install -e ".[bench]"`) parses
and analyses the candump log in memory, `canopen_lens.open_log` (its
`Trace.from_bytes`) with the same EDS attached to the 16 nodes; without it its
rows say so. Logs come from benchmarks/generate.py and are kept in --out
(default benchmarks/out, git-ignored) for the next run; --clean deletes the ones
this run generated.

`--against PATH` (a checkout of another commit, its compiled helper built in
place) runs every figure's command for both trees, one after the other in the
same rounds (the other tree's processes with PYTHONPATH=PATH, in PATH), and
prints both trees' best CPU (user + system) and wall seconds side by side with
their ratios, this tree over the other (`--only TEXT`: just the figures whose
label contains TEXT, e.g. `--only "read only .blf"`). python-can's and
canopen-lens's figures are the same for both trees and are left out.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))  # benchmarks/: the generator's log names
from generate import log_stem  # noqa: E402

ROOT = HERE.parent
# issue 43 (issue 23's were 9x, 12x, 6x): export --parquet CPU, python-can's LogReader
# over ours, per format; and at most this much the CPU of its library floor (bench_floor)
RATIO_TARGET = {".log": 12.0, ".asc": 15.0, ".blf": 8.0}
FLOOR_TARGET = 1.25
FRAMES_TARGET = {".log": 5e6}  # wall, on a quiet machine
EDS = ROOT / "decoders" / "dat7014.eds"
HEADING = "-- "  # a row that starts a section of the table
DEVICES = [arg for k in range(1, 17) for arg in ("--device", f"{k}=dat7014")]
CLI = [sys.executable, "-m", "cananalyze"]
# Measured as installed: bytecode cached. With PYTHONDONTWRITEBYTECODE set (some CI images
# and this machine set it) every process would recompile every module, ~0.2 s each.
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
# prints the loop's wall and CPU seconds and the frames it read (for scaling a prefix)
PYCAN = """
import itertools, sys, time
import can
reader = can.LogReader(sys.argv[1])
limit = int(sys.argv[2])
n = 0
w, c = time.perf_counter(), time.process_time()
for _ in (itertools.islice(reader, limit) if limit else reader):
    n += 1
print(time.perf_counter() - w, time.process_time() - c, n)
"""
# canopen-lens's C++ core: parse and analyse the log in memory, the EDS on 16 nodes
LENS = """
import sys
from canopen_lens import open_log
log = open_log(sys.argv[1], eds={k: sys.argv[2] for k in range(1, 17)})
assert len(log) > 0, "canopen-lens read no frame"
"""
# the reader alone: every batch of the log, nothing decoded (the tree's cananalyze)
READER = """
import sys
from cananalyze.formats.source import open_log
src = open_log(sys.argv[1])
print(sum(len(b) for b in src.batches()))
"""


class Run:
    """Best wall and CPU seconds, highest peak RSS (MB) of repeated runs of one command.

    `tree`: the checkout whose cananalyze the command runs (its processes start in it,
    with PYTHONPATH set to it); this one by default. `strict`: a failed run ends the
    benchmark; otherwise it is kept as `failed` (its exit code) and the figure left out.
    """

    def __init__(
        self,
        cmd: list[str],
        ok: tuple[int, ...] = (0,),
        tree: Path = ROOT,
        strict: bool = True,
        after=None,
    ) -> None:
        self.cmd, self.ok, self.tree, self.strict, self.after = cmd, ok, tree, strict, after
        self.wall = self.cpu = float("inf")
        self.user = self.system = float("inf")  # the best CPU run's, apart
        self.mb = 0.0
        self.cpus: list[float] = []  # every round's, in order (per-round ratios)
        self.walls: list[float] = []  # every round's wall, in order (medians)
        self.load = 0.0  # 1-minute load average when the best wall run started
        self.failed: int | None = None

    def once(self) -> None:
        if self.failed is not None:
            return
        env = dict(ENV, PYTHONPATH=str(self.tree))
        load = os.getloadavg()[0]
        with tempfile.TemporaryFile("w+") as out:
            t = time.perf_counter()
            proc = subprocess.Popen(
                self.cmd, stdout=out, stderr=subprocess.DEVNULL, cwd=self.tree, env=env
            )
            _, status, usage = os.wait4(proc.pid, 0)
            wall = time.perf_counter() - t
            out.seek(0)
            printed = out.read()
        if self.after is not None:
            self.after()
        code = os.waitstatus_to_exitcode(status)
        if code not in self.ok:
            if self.strict:
                raise SystemExit(f"failed ({code}): {' '.join(self.cmd)}")
            self.failed = code
            return
        cpu = usage.ru_utime + usage.ru_stime
        wall, cpu = self.scaled(printed, wall, cpu)
        self.walls.append(wall)
        if wall < self.wall:
            self.wall, self.load = wall, load
        if cpu < self.cpu:
            self.user, self.system = usage.ru_utime, usage.ru_stime
        self.cpu = min(self.cpu, cpu)
        self.cpus.append(cpu)
        self.mb = max(self.mb, usage.ru_maxrss / 1024)

    def scaled(self, printed: str, wall: float, cpu: float) -> tuple[float, float]:
        """The figures of one run from what it printed (as measured here)."""
        return wall, cpu


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


def ensure(out: Path, n: int, suffixes: list[str], made: list[Path], faults: bool = False) -> Path:
    """The generator's n-frame logs, generated when missing (the time it took is printed);
    `faults`: its faulty bus's."""
    stem = log_stem(out, n, faults)
    missing = [s for s in suffixes if not stem.with_suffix(s).exists()]
    if missing:
        t = time.perf_counter()
        bus = "faulty bus " if faults else ""
        print(f"generating {n:,} frames ({bus}{','.join(missing)}) in {out} ...", flush=True)
        argv = [sys.executable, str(HERE / "generate.py"), str(n), str(stem), ",".join(missing)]
        subprocess.run(
            argv + (["--faults"] if faults else []), check=True, stdout=subprocess.DEVNULL
        )
        made += [stem.with_suffix(s) for s in missing]
        print(f"  took {time.perf_counter() - t:.1f} s", flush=True)
    return stem


class PyCanRun(Run):
    """python-can LogReader's whole-process time over the file; scaled from a prefix if asked:
    start-up as measured, the loop (wall and CPU) scaled to the whole file."""

    def __init__(self, path: Path, n: int, prefix: int) -> None:
        self.n = n
        self.limit = prefix if 0 < prefix < n else 0
        super().__init__([sys.executable, "-c", PYCAN, str(path), str(self.limit)])
        lim = self.limit
        self.how = f"first {lim / 1e6:g}M frames, scaled x{n / lim:g}" if lim else "whole file"

    def scaled(self, printed: str, wall: float, cpu: float) -> tuple[float, float]:
        loop_wall, loop_cpu, count = printed.split()
        if not self.limit:
            return wall, cpu
        k = self.n / int(count)
        return wall + float(loop_wall) * (k - 1), cpu + float(loop_cpu) * (k - 1)


def lens_run(path: Path) -> Run | None:
    """canopen-lens on the log with the EDS on 16 nodes, or None when it is not installed."""
    if importlib.util.find_spec("canopen_lens") is None:
        return None
    return Run([sys.executable, "-c", LENS, str(path), str(EDS)], strict=False)


def reader_run(path: Path, tree: Path = ROOT) -> Run:
    return Run([sys.executable, "-c", READER, str(path)], tree=tree, strict=False)


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
    ap.add_argument(
        "--against",
        type=Path,
        metavar="PATH",
        help="also run every figure for the checkout at PATH (compiled helper built), "
        "in the same rounds, and print both side by side",
    )
    ap.add_argument(
        "--only",
        metavar="TEXT",
        help="with --against: only the figures whose label contains TEXT (e.g. 'read only .blf')",
    )
    args = ap.parse_args(argv)
    n = int(1e6 if args.quick else args.size)
    formats = args.formats.split(",")
    args.out = args.out.resolve()  # the other tree's processes run in their own folder
    args.out.mkdir(parents=True, exist_ok=True)
    if args.against is not None:
        args.against = args.against.resolve()
        if not (args.against / "cananalyze" / "__init__.py").is_file():
            ap.error(f"--against {args.against}: no cananalyze package there")
    made: list[Path] = []
    load0 = os.getloadavg()
    try:
        if args.against is not None:
            lines = compare(args, n, formats, made)
        else:
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
    if args.against is not None:
        print("\n".join(lines))
        return 0
    width = max(len(r[0]) for r in rows)
    for name, value, target, verdict in rows:
        if name.startswith(HEADING):
            print(name)
        else:
            print(f"{name:<{width}}  {value:<48} {target:<14} {verdict}")
    return 0


def commands(
    stem: Path, formats: list[str], tmp: Path, timeline_log: Path, faulty_log: Path
) -> list[tuple]:
    """Every figure's command: (label, command line, exit codes that are fine, file or
    folder the run leaves behind). The headline exports, decode --summary, the reader
    alone and check per format (check on the healthy bus must exit 0; on the faulty bus,
    `faulty_log`, beside its own decode --summary, it exits 1), the text outputs, the
    timeline exports, start-up."""
    out = []
    pq = tmp / "pq"
    for k, suffix in enumerate(formats):
        log = str(stem.with_suffix(suffix))
        export = ["export", log, "--parquet", str(pq), *DEVICES, "-q"]
        out.append((f"export --parquet {suffix}", CLI + export, (0,), pq))
        summary = CLI + ["decode", log, "--summary", *DEVICES]
        out.append((f"decode --summary {suffix}", summary, (0,), None))
        out.append((f"read only {suffix}", [sys.executable, "-c", READER, log], (0,), None))
        if k == 0:  # check's overhead over the same decode
            out.append((f"check {suffix}", CLI + ["check", log, *DEVICES], (0,), None))
    bad = str(faulty_log)
    summary = CLI + ["decode", bad, "--summary", *DEVICES]
    out.append(("decode --summary (faulty bus .log)", summary, (0,), None))
    out.append(("check (faulty bus .log)", CLI + ["check", bad, *DEVICES], (1,), None))
    log = str(stem.with_suffix(formats[0]))
    dest = tmp / "out.txt"
    for devices, fmt, what in (
        ([], "text", "no devices"),
        (DEVICES, "text", "16 devices"),
        ([], "jsonl", "no devices, jsonl"),
    ):
        argv = CLI + ["decode", log, *devices, "--format", fmt, "-o", str(dest)]
        out.append((f"decode -o FILE ({formats[0]}, {what})", argv, (0,), dest))
    for kind in ("mcap", "rrd"):
        dest = tmp / f"t.{kind}"
        argv = CLI + ["export", str(timeline_log), f"--{kind}", str(dest), *DEVICES, "-q"]
        out.append((f"export --{kind} (.log, 16 devices)", argv, (0,), dest))
    out.append(("cananalyze --help", CLI + ["--help"], (0,), None))
    return out


def _remove(path: Path | None):
    def clean() -> None:
        if path is None:
            return
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)

    return clean


def _compile(tree: Path) -> None:
    """Byte-compile the tree's package first, as `pip install` does: otherwise the first
    run of a figure (all of them with --repeat 1) also pays ~0.35 s CPU compiling."""
    subprocess.run(
        [sys.executable, "-m", "compileall", "-q", str(tree / "cananalyze")],
        env=ENV,
        check=True,
        stdout=subprocess.DEVNULL,
    )


def _check_tree(tree: Path) -> None:
    """The tree's processes import its own cananalyze (not an installed one)."""
    probe = "import cananalyze; print(cananalyze.__file__)"
    env = dict(ENV, PYTHONPATH=str(tree))
    done = subprocess.run(
        [sys.executable, "-c", probe], cwd=tree, env=env, capture_output=True, text=True
    )
    where = Path(done.stdout.strip() or "?").resolve()
    if done.returncode != 0 or not where.is_relative_to(tree):
        raise SystemExit(f"{tree}: its processes import cananalyze from {where}, not from it")


def compare(args, n: int, formats: list[str], made: list[Path]) -> list[str]:
    """Every figure for this tree and the other, interleaved in the same rounds (the two
    commands of a figure back to back, which goes first alternating by round), so a
    change in the machine's load shows in both columns alike."""
    other = args.against
    if not list((other / "cananalyze").rglob("_speedups*.so")):
        print(f"warning: {other} has no compiled helper (_speedups): its figures are slower")
    for tree in (ROOT, other):
        _check_tree(tree)
        _compile(tree)
    stem = ensure(args.out, n, formats, made)
    timeline_log = ensure(args.out, n, [".log"], made).with_suffix(".log")
    faulty_log = ensure(args.out, n, [".log"], made, faults=True).with_suffix(".log")
    pairs = []
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        every = commands(stem, formats, Path(tmp), timeline_log, faulty_log)
        for label, argv, ok, leaves in every:
            if args.only and args.only not in label:
                continue
            mine = Run(argv, ok, ROOT, strict=False, after=_remove(leaves))
            theirs = Run(argv, ok, other, strict=False, after=_remove(leaves))
            pairs.append((label, mine, theirs))
        print(f"{len(pairs)} figures x 2 trees, {args.repeat} rounds ...", flush=True)
        for k in range(args.repeat):
            for _, mine, theirs in pairs:
                for run in (mine, theirs) if k % 2 == 0 else (theirs, mine):
                    run.once()
    width = max(len(label) for label, _, _ in pairs)
    head = f"{'':<{width}}  {'this tree':>24}  {'other tree':>24}  {'this / other':>21}"
    cols = f"{'cpu':>8} {'wall':>8} {'RSS':>6}"
    out = [
        f"this tree: {ROOT}",
        f"other tree (--against): {other}",
        head,
        f"{'':<{width}}  {cols}  {cols}  {'cpu':>6} {'wall':>7} {'RSS':>6}",
    ]

    def cell(run: Run) -> str:
        if run.failed is not None:
            return f"{'failed (' + str(run.failed) + ')':>24}"
        return f"{run.cpu:7.2f}s {run.wall:7.2f}s {run.mb:5.0f}M"

    for label, mine, theirs in pairs:
        if mine.failed is None and theirs.failed is None:
            ratio = f"{mine.cpu / theirs.cpu:5.2f}x {mine.wall / theirs.wall:6.2f}x"
            ratio += f" {mine.mb / theirs.mb:5.2f}x"
        else:
            ratio = f"{'-':>21}"
        out.append(f"{label:<{width}}  {cell(mine)}  {cell(theirs)}  {ratio}")
    # the same figures as medians of the rounds (best-of above: the machine's quietest)
    med = statistics.median
    out += [
        "",
        f"medians of {args.repeat} rounds:",
        f"{'':<{width}}  {'this tree':>17}  {'other tree':>17}  {'this / other':>14}",
        f"{'':<{width}}  {'cpu':>8} {'wall':>8}  {'cpu':>8} {'wall':>8}  {'cpu':>6} {'wall':>7}",
    ]
    for label, mine, theirs in pairs:
        if mine.failed is not None or theirs.failed is not None or not mine.cpus:
            continue
        a, b = (med(mine.cpus), med(mine.walls)), (med(theirs.cpus), med(theirs.walls))
        out.append(
            f"{label:<{width}}  {a[0]:7.2f}s {a[1]:7.2f}s  {b[0]:7.2f}s {b[1]:7.2f}s  "
            f"{a[0] / b[0]:5.2f}x {a[1] / b[1]:6.2f}x"
        )
    return out


def measure(args, n: int, formats: list[str], made: list[Path]) -> list[tuple[str, str, str, str]]:
    _compile(ROOT)
    stem = ensure(args.out, n, formats, made)
    per_format = {}
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        pq = Path(tmp) / "pq"
        timeline_log = ensure(args.out, n, [".log"], made).with_suffix(".log")
        faulty_log = ensure(args.out, n, [".log"], made, faults=True).with_suffix(".log")
        # the same commands --against runs, by label
        every = commands(stem, formats, Path(tmp), timeline_log, faulty_log)
        cmd = {c[0]: (c[1], c[2]) for c in every}
        for k, suffix in enumerate(formats):
            log = stem.with_suffix(suffix)
            f = {
                "export": Run(*cmd[f"export --parquet {suffix}"]),
                "summary": Run(*cmd[f"decode --summary {suffix}"]),
                "reader": Run(*cmd[f"read only {suffix}"]),
                "pycan": PyCanRun(log, n, int(args.pycan_prefix)),
            }
            if suffix == ".log":
                f["lens"] = lens_run(log)
            if k == 0:  # check's overhead over the same decode, in the same rounds
                f["check"] = Run(*cmd[f"check {suffix}"])
            what = ", ".join(name for name, run in f.items() if run is not None)
            print(f"{suffix}: {what}, in {args.repeat} rounds ...", flush=True)
            rounds([run for run in f.values() if run is not None], args.repeat)
            shutil.rmtree(pq, ignore_errors=True)
            per_format[suffix] = f
        # the checks' cost where they find something: the faulty bus, check over its decode
        print("faulty bus: decode --summary, check ...", flush=True)
        faulty = {
            "summary": Run(*cmd["decode --summary (faulty bus .log)"]),
            "check": Run(*cmd["check (faulty bus .log)"]),
        }
        rounds(list(faulty.values()), args.repeat)
        print("text output ...", flush=True)
        text_runs = []
        for what in ("no devices", "16 devices", "no devices, jsonl"):
            dest = Path(tmp) / "out.txt"
            argv, ok = cmd[f"decode -o FILE ({formats[0]}, {what})"]
            run = measured(argv, 1 if "jsonl" in what else args.repeat, ok)
            with open(dest, "rb") as fh:
                lines = sum(chunk.count(b"\n") for chunk in iter(lambda: fh.read(1 << 24), b""))
            dest.unlink()
            text_runs.append((run, lines, what))
        # the timeline exports stream too: their peak at this size and at 5M
        timelines = []
        for kind, dest in (("mcap", Path(tmp) / "t.mcap"), ("rrd", Path(tmp) / "t.rrd")):
            print(f"export --{kind} ...", flush=True)
            got = [measured(cmd[f"export --{kind} (.log, 16 devices)"][0], 1)]
            dest.unlink(missing_ok=True)
            if n > 5e6:  # and at 5M: flat in log length
                s = ensure(args.out, int(5e6), [".log"], made).with_suffix(".log")
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
        help_run = measured(cmd["cananalyze --help"][0], max(5, args.repeat))
    return (
        cpu_rows(per_format, formats, faulty)
        + wall_rows(per_format, formats, n, text_runs, timelines)
        + memory_rows(per_format, flat, n, args.flat)
        + [("cananalyze --help", f"{help_run.wall:.3f} s", "< 0.3 s", mark(help_run.wall < 0.3))]
    )


def _ratio(a: float, b: float) -> str:
    return f"{a / b:5.1f}x  ({a:.2f} s / {b:.2f} s)"


def _per_round(pycan: Run, export: Run, suffix: str) -> tuple[str, str, str, str]:
    """Each round's python-can over the same round's export: the best of each side may
    come from different rounds, and this machine's speed for the export moves more
    than for python-can's loop, so the spread says how far one run's ratio can be
    trusted."""
    got = sorted(p / e for p, e in zip(pycan.cpus, export.cpus, strict=True))
    name = f"  per round, export --parquet {suffix}"
    if not got:
        return (name, "no round", "", "")
    mid = statistics.median(got)
    return (name, f"{mid:5.1f}x median ({got[0]:.1f}x-{got[-1]:.1f}x, {len(got)} rounds)", "", "")


def cpu_rows(per_format: dict, formats: list[str], faulty: dict) -> list[tuple[str, str, str, str]]:
    """1. CPU seconds (user + system): the issue's targets are these ratios. check's
    overhead on the healthy bus (the target) and on the faulty one (`faulty`: its
    decode --summary and check runs)."""
    rows = [(f"{HEADING}CPU seconds (user + system), both sides in the same rounds", "", "", "")]
    for suffix, f in per_format.items():
        pc, export = f["pycan"], f["export"]
        target = RATIO_TARGET.get(suffix)
        rows.append(
            (
                f"python-can LogReader / export --parquet {suffix}, cpu",
                _ratio(pc.cpu, export.cpu),
                f">= {target:g}x" if target else "(reference)",
                mark(pc.cpu / export.cpu >= target) if target else "",
            )
        )
    for suffix, f in per_format.items():
        rows.append(_per_round(f["pycan"], f["export"], suffix))
    if ".log" in per_format:
        lens, export = per_format[".log"]["lens"], per_format[".log"]["export"]
        name = "canopen-lens / export --parquet .log, cpu"
        if lens is None:
            rows.append((name, 'not installed: pip install -e ".[bench]"', "> 1x", ""))
        elif lens.failed is not None:
            rows.append((name, f"canopen-lens failed ({lens.failed})", "> 1x", ""))
        else:
            ahead = lens.cpu / export.cpu
            rows.append((name, _ratio(lens.cpu, export.cpu), "> 1x", mark(ahead > 1)))
            rows.append(  # a lower system CPU (memory mapped, fewer pages touched) shows here
                (
                    "  user + system, canopen-lens vs export",
                    f"{lens.user:.2f} + {lens.system:.2f} s vs "
                    f"{export.user:.2f} + {export.system:.2f} s",
                    "",
                    "",
                )
            )
    for suffix, f in per_format.items():
        rows.append(
            (
                f"python-can LogReader / decode --summary {suffix}, cpu",
                _ratio(f["pycan"].cpu, f["summary"].cpu),
                "(reference)",
                "",
            )
        )
    for suffix, f in per_format.items():  # what the reader alone costs of the export
        reader, pc = f["reader"], f["pycan"]
        rows.append(
            (
                f"python-can LogReader / read only {suffix}, cpu",
                _ratio(pc.cpu, reader.cpu),
                "(reference)",
                "",
            )
        )
    hows = sorted({f["pycan"].how for f in per_format.values()})
    rows.append(("  python-can timed on", "; ".join(hows), "", ""))
    first = per_format[formats[0]]
    check, base = first["check"], first["summary"]
    over = check.cpu / base.cpu - 1
    rows.append(
        (
            f"check vs decode --summary ({formats[0]}), cpu",
            f"{100 * over:+5.1f} %  ({check.cpu:.2f} s vs {base.cpu:.2f} s)",
            "<= +25 %",
            mark(over <= 0.25),
        )
    )
    check, base = faulty["check"], faulty["summary"]
    over = check.cpu / base.cpu - 1
    rows.append(
        (
            "check vs decode --summary (faulty bus .log), cpu",
            f"{100 * over:+5.1f} %  ({check.cpu:.2f} s vs {base.cpu:.2f} s)",
            "(reference)",
            "",
        )
    )
    return rows


def _wall(run: Run) -> str:
    """Wall seconds with the CPU and the load average the best run started at."""
    return f"{run.wall:.2f} s, cpu {run.cpu:.2f} s, load {run.load:.1f}"


def wall_rows(
    per_format: dict, formats: list[str], n: int, text_runs: list, timelines: list
) -> list[tuple[str, str, str, str]]:
    """2. Wall figures, each with the load average beside it (they swing with it)."""
    rows = [(f"{HEADING}wall seconds, the 1-minute load average beside", "", "", "")]
    for suffix, f in per_format.items():
        export = f["export"]
        target = FRAMES_TARGET.get(suffix)
        rate = n / export.wall
        rows.append(
            (
                f"export --parquet {suffix} frames/s",
                f"{rate / 1e6:5.2f}M  ({_wall(export)}, {export.mb:.0f} MB)",
                f">= {target / 1e6:g}M (quiet)" if target else "(reference)",
                mark(rate >= target) if target else "",
            )
        )
    for suffix, f in per_format.items():
        pc, export = f["pycan"], f["export"]
        rows.append(
            (
                f"python-can LogReader / export --parquet {suffix}, wall",
                f"{_ratio(pc.wall, export.wall)}, load {export.load:.1f}",
                "(reference)",
                "",
            )
        )
    for suffix, f in per_format.items():
        for key, what in (("summary", "decode --summary"), ("reader", "read only")):
            run = f[key]
            rows.append(
                (
                    f"{what} {suffix} frames/s",
                    f"{n / run.wall / 1e6:5.2f}M  ({_wall(run)})",
                    "(reference)",
                    "",
                )
            )
    lens = per_format.get(".log", {}).get("lens")
    if lens is not None and lens.failed is None:
        rows.append(
            (
                "canopen-lens .log frames/s",
                f"{n / lens.wall / 1e6:5.2f}M  ({_wall(lens)}, {lens.mb:.0f} MB)",
                "(reference)",
                "",
            )
        )
    first = per_format[formats[0]]
    check, base = first["check"], first["summary"]
    over = check.wall / base.wall - 1
    rows.append(
        (
            f"check vs decode --summary ({formats[0]}), wall",
            f"{100 * over:+5.1f} %  ({check.wall:.2f} s vs {base.wall:.2f} s, load {check.load:.1f})",
            "<= +25 %",
            mark(over <= 0.25),
        )
    )
    for run, lines, what in text_runs:  # JSONL: a reference figure, best of one run
        rate = lines / run.wall
        text = "jsonl" not in what
        rows.append(
            (
                f"decode -o FILE ({formats[0]}, {what}) lines/s",
                f"{rate / 1e6:5.2f}M  ({lines:,} lines, {_wall(run)})",
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
                f"{n / run.wall / 1e6:5.2f}M  ({_wall(run)}, {run.mb:.0f} MB{at5})",
                "(reference)",
                "",
            )
        )
    return rows


def memory_rows(per_format: dict, flat: list, n: int, asked: float) -> list[tuple]:
    """3. Peak memory at this size, and flat in log length."""
    peak = max(f["export"].mb for f in per_format.values())
    rows = [
        (f"{HEADING}memory and start-up", "", "", ""),
        (
            f"peak RSS export --parquet at {n / 1e6:g}M",
            f"{peak:.0f} MB",
            "<= 600 MB" if n >= 10e6 else "(600 MB at 10M)",
            mark(peak <= 600) if n >= 10e6 else "",
        ),
    ]
    if flat:
        (s5, r5), (sb, rb) = flat
        ratio = rb.mb / r5.mb - 1
        more = "" if asked else "; 50M: --flat 50e6"
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
    return rows


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
