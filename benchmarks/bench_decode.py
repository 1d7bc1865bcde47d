"""Every performance figure of issue 10 in one command, ratios first.

    python benchmarks/bench_decode.py                 # the issue's 10M-frame logs (~10 min)
    python benchmarks/bench_decode.py --quick         # 1M frames (~2 min)
    python benchmarks/bench_decode.py --flat 50e6     # flatness 5M vs 50M (a 2.1 GB candump)
    python benchmarks/bench_decode.py --quick --against ../baseline   # this tree vs another

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

`--against PATH` (a checkout of another commit, its compiled helper built in
place) runs every figure's command for both trees, one after the other in the
same rounds (the other tree's processes with PYTHONPATH=PATH, in PATH), and
prints both trees' best wall and CPU (user + system) seconds side by side with
their ratios, this tree over the other. python-can's figures are the same for
both trees and are left out.
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
        self.mb = 0.0
        self.failed: int | None = None

    def once(self) -> None:
        if self.failed is not None:
            return
        env = dict(ENV, PYTHONPATH=str(self.tree))
        t = time.perf_counter()
        proc = subprocess.Popen(
            self.cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=self.tree, env=env
        )
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t
        if self.after is not None:
            self.after()
        code = os.waitstatus_to_exitcode(status)
        if code not in self.ok:
            if self.strict:
                raise SystemExit(f"failed ({code}): {' '.join(self.cmd)}")
            self.failed = code
            return
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
    ap.add_argument(
        "--against",
        type=Path,
        metavar="PATH",
        help="also run every figure for the checkout at PATH (compiled helper built), "
        "in the same rounds, and print both side by side",
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
        print(f"{name:<{width}}  {value:<48} {target:<14} {verdict}")
    return 0


def commands(stem: Path, formats: list[str], tmp: Path, timeline_log: Path) -> list[tuple]:
    """Every figure's command: (label, `cananalyze` arguments, exit codes that are fine,
    file or folder the run leaves behind). The headline exports, decode --summary and
    check per format, the text outputs, the timeline exports, start-up."""
    out = []
    pq = tmp / "pq"
    for k, suffix in enumerate(formats):
        log = str(stem.with_suffix(suffix))
        out.append(
            (f"export --parquet {suffix}", ["export", log, "--parquet", str(pq), *DEVICES, "-q"])
            + ((0,), pq)
        )
        out.append(
            (f"decode --summary {suffix}", ["decode", log, "--summary", *DEVICES], (0,), None)
        )
        if k == 0:  # check's overhead over the same decode
            out.append((f"check {suffix}", ["check", log, *DEVICES], (0, 1), None))
    log = str(stem.with_suffix(formats[0]))
    dest = tmp / "out.txt"
    for devices, fmt, what in (
        ([], "text", "no devices"),
        (DEVICES, "text", "16 devices"),
        ([], "jsonl", "no devices, jsonl"),
    ):
        argv = ["decode", log, *devices, "--format", fmt, "-o", str(dest)]
        out.append((f"decode -o FILE ({formats[0]}, {what})", argv, (0,), dest))
    for kind in ("mcap", "rrd"):
        dest = tmp / f"t.{kind}"
        argv = ["export", str(timeline_log), f"--{kind}", str(dest), *DEVICES, "-q"]
        out.append((f"export --{kind} (.log, 16 devices)", argv, (0,), dest))
    out.append(("cananalyze --help", ["--help"], (0,), None))
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
    stem = ensure(args.out, n, formats, made)
    timeline_log = ensure(args.out, n, [".log"], made).with_suffix(".log")
    pairs = []
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        for label, argv, ok, leaves in commands(stem, formats, Path(tmp), timeline_log):
            mine = Run(CLI + argv, ok, ROOT, strict=False, after=_remove(leaves))
            theirs = Run(CLI + argv, ok, other, strict=False, after=_remove(leaves))
            pairs.append((label, mine, theirs))
        print(f"{len(pairs)} figures x 2 trees, {args.repeat} rounds ...", flush=True)
        for k in range(args.repeat):
            for _, mine, theirs in pairs:
                for run in (mine, theirs) if k % 2 == 0 else (theirs, mine):
                    run.once()
    width = max(len(label) for label, _, _ in pairs)
    head = f"{'':<{width}}  {'this tree':>17}  {'other tree':>17}  {'this / other':>14}"
    out = [
        f"this tree: {ROOT}",
        f"other tree (--against): {other}",
        head,
        f"{'':<{width}}  {'wall':>8} {'cpu':>8}  {'wall':>8} {'cpu':>8}  {'wall':>6} {'cpu':>7}",
    ]

    def cell(run: Run) -> str:
        if run.failed is not None:
            return f"{'failed (' + str(run.failed) + ')':>17}"
        return f"{run.wall:7.2f}s {run.cpu:7.2f}s"

    for label, mine, theirs in pairs:
        if mine.failed is None and theirs.failed is None:
            ratio = f"{mine.wall / theirs.wall:5.2f}x {mine.cpu / theirs.cpu:6.2f}x"
        else:
            ratio = f"{'-':>14}"
        out.append(f"{label:<{width}}  {cell(mine)}  {cell(theirs)}  {ratio}")
    return out


def measure(args, n: int, formats: list[str], made: list[Path]) -> list[tuple[str, str, str, str]]:
    stem = ensure(args.out, n, formats, made)
    rows: list[tuple[str, str, str, str]] = []
    per_format = {}
    with tempfile.TemporaryDirectory(dir=args.out) as tmp:
        pq = Path(tmp) / "pq"
        timeline_log = ensure(args.out, n, [".log"], made).with_suffix(".log")
        # the same commands --against runs, by label
        cmd = {c[0]: (CLI + c[1], c[2]) for c in commands(stem, formats, Path(tmp), timeline_log)}
        for k, suffix in enumerate(formats):
            what = "export --parquet, decode --summary, python-can LogReader"
            export = Run(*cmd[f"export --parquet {suffix}"])
            summary = Run(*cmd[f"decode --summary {suffix}"])
            runs = [export, summary, PyCanRun(stem.with_suffix(suffix), n, int(args.pycan_prefix))]
            if k == 0:  # check's overhead over the same decode, in the same rounds
                check = Run(*cmd[f"check {suffix}"])
                runs.append(check)
                what += ", check"
            print(f"{suffix}: {what}, in {args.repeat} rounds ...", flush=True)
            rounds(runs, args.repeat)
            shutil.rmtree(pq, ignore_errors=True)
            per_format[suffix] = (export, summary, runs[2].wall, runs[2].how)
        base = per_format[formats[0]][1]
        print("text output ...", flush=True)
        text_runs = []
        for what in ("no devices", "16 devices", "no devices, jsonl"):
            dest = Path(tmp) / "out.txt"
            argv, ok = cmd[f"decode -o FILE ({formats[0]}, {what})"]
            run = measured(argv, 1 if "jsonl" in what else args.repeat, ok)
            with open(dest, "rb") as f:
                lines = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 24), b""))
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
