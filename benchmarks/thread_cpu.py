"""CPU seconds of each thread of one cananalyze command, medians over rounds, two trees interleaved.

    python benchmarks/thread_cpu.py --repeat 5 --against ../main -- export LOG --parquet DIR -q

Each round runs the command in a fresh process per tree (PYTHONPATH set to the tree), with
`threading.Thread.run` wrapped to read the thread's own clock (`time.thread_time()`) when it
ends, and the main thread's read at exit; threads of one name (the two Parquet writers)
are summed. A `--parquet`/`--csv`/`--mcap` destination is removed before each run. Printed:
per thread, the median over the rounds for each tree and their ratio, beside the process's
CPU (user + system) from `os.wait4`.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
# run inside the measured process: the command as `python -m cananalyze ARGS`
PROBE = """
import atexit, json, runpy, sys, threading, time
out, spent = sys.argv[1], {}
run = threading.Thread.run
def timed(self):
    try:
        run(self)
    finally:
        name = self.name.split(" (")[0].rstrip("-0123456789") or "thread"
        spent[name] = spent.get(name, 0.0) + time.thread_time()
threading.Thread.run = timed
def dump():
    spent["main"] = time.thread_time()
    with open(out, "w") as f:
        json.dump(spent, f)
atexit.register(dump)
sys.argv = ["cananalyze", *sys.argv[2:]]
runpy.run_module("cananalyze", run_name="__main__")
"""
DESTS = ("--parquet", "--csv", "--mcap", "--rrd", "-o")


def once(tree: Path, args: list[str]) -> dict[str, float]:
    for flag, value in zip(args, args[1:], strict=False):
        if flag in DESTS:
            shutil.rmtree(value, ignore_errors=True) if Path(value).is_dir() else None
            Path(value).unlink(missing_ok=True) if Path(value).is_file() else None
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        dump = Path(f.name)
    try:
        proc = subprocess.Popen(
            [sys.executable, "-c", PROBE, str(dump), *args],
            cwd=tree,
            env=dict(ENV, PYTHONPATH=str(tree)),
            stdout=subprocess.DEVNULL,
        )
        _, status, usage = os.wait4(proc.pid, 0)
        if os.waitstatus_to_exitcode(status) not in (0, 1):
            raise SystemExit(f"{tree}: the command exited {os.waitstatus_to_exitcode(status)}")
        spent = json.loads(dump.read_text())
    finally:
        dump.unlink(missing_ok=True)
    spent["process (user+sys)"] = usage.ru_utime + usage.ru_stime
    return spent


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="rounds (medians printed)")
    ap.add_argument("--against", type=Path, help="another checkout, run in the same rounds")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- then cananalyze's arguments")
    args = ap.parse_args(argv)
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not cmd:
        ap.error("no command given (-- export LOG --parquet DIR ...)")
    trees = [ROOT] + ([args.against.resolve()] if args.against else [])
    rounds: list[list[dict[str, float]]] = [[] for _ in trees]
    for _ in range(args.repeat):
        for k, tree in enumerate(trees):
            rounds[k].append(once(tree, cmd))
    names = sorted({n for r in rounds for s in r for n in s}, key=lambda n: (n != "main", n))
    names.remove("process (user+sys)")
    names.append("process (user+sys)")
    print(f"cananalyze {' '.join(cmd)}")
    print(f"CPU seconds, medians of {args.repeat} rounds; load average {os.getloadavg()[0]:.1f}")
    head = f"{'thread':<24}" + "".join(f"{str(t)[-22:]:>24}" for t in trees)
    print(head + ("   this / other" if len(trees) > 1 else ""))
    for name in names:
        med = [statistics.median(s.get(name, 0.0) for s in r) for r in rounds]
        line = f"{name:<24}" + "".join(f"{m:>23.2f}s" for m in med)
        if len(trees) > 1:
            line += f"   {med[0] / med[1]:.2f}x" if med[1] else "   -"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
