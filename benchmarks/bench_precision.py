"""Precision of `cananalyze check`: findings per rule and per 1,000 frames on real logs.

Runs `check --json` in fresh processes over every log under the real-data folder
(third-party captures, `../shared/data/real`) and over python-canopen traffic in which
the configuration changes while the bus runs (tests/helpers/config_traffic: nothing in
it is a fault, so every finding there is a false alarm). With `--against TREE` the same
logs are checked by another checkout too, interleaved, for a before/after table.
Findings are counted from the JSON; where an older tree folded them into a "N more
like this not listed (M in all)" row, M counts (its JSON could lose listed rows). CPU (user + system) beside wall time.

    python benchmarks/bench_precision.py [--data DIR] [--against TREE] [--limit N]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = ROOT.parent / "shared" / "data" / "real"
SKIP_SUFFIXES = {".md", ".py", ".eds", ".dcf", ".json", ".yaml", ".yml", ".toml", ".xml"}
MORE = re.compile(r"(\d+) more like this not listed \((\d+) in all\)")


def real_logs(data: Path) -> list[Path]:
    """Every file under `data` that may be a log (documentation and device files left out)."""
    if not data.is_dir():
        return []
    return sorted(
        p
        for p in data.rglob("*")
        if p.is_file() and p.suffix.lower() not in SKIP_SUFFIXES and p.name != "SOURCES.md"
    )


def stack_logs(out: Path) -> list[tuple[Path, Path]]:
    """The python-canopen scenarios as candump logs and their rules files (made once)."""
    sys.path.insert(0, str(ROOT))
    from cananalyze.core.frames import from_rows
    from cananalyze.formats.logfile import write_log
    from tests.helpers.config_traffic import SCENARIOS

    out.mkdir(parents=True, exist_ok=True)
    made = []
    for name, scenario in SCENARIOS.items():
        log, rules = out / f"{name}.log", out / f"{name}.rules.yaml"
        if not log.exists():
            rows, text = scenario()
            write_log(from_rows(sorted(rows, key=lambda r: r[0])), log)
            rules.write_text(text)
        made.append((log, rules))
    return made


def frames_of(log: Path) -> int | None:
    from cananalyze.pipeline import open_source

    try:
        return sum(len(b) for b in open_source(log).batches())
    except Exception:  # unreadable: reported as such, not counted
        return None


def check(tree: Path, log: Path, rules: Path | None) -> tuple[Counter | None, float, float]:
    """(findings per rule, CPU s, wall s) of `check --json` by the checkout at `tree`."""
    with tempfile.TemporaryDirectory() as tmp:
        dest = Path(tmp) / "f.json"
        cmd = [sys.executable, "-m", "cananalyze", "check", str(log), "-q", "--json", str(dest)]
        if rules is not None:
            cmd += ["--rules", str(rules)]
        env = {**os.environ, "PYTHONPATH": str(tree)}
        t = time.perf_counter()
        proc = subprocess.Popen(
            cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=tree
        )
        _, status, usage = os.wait4(proc.pid, 0)
        err = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
        wall = time.perf_counter() - t
        cpu = usage.ru_utime + usage.ru_stime
        if os.waitstatus_to_exitcode(status) not in (0, 1) or not dest.exists():
            if rules is not None and "jitter_ms" in err:  # an older tree: no jitter floor
                plain = Path(tmp) / "rules.yaml"
                plain.write_text(
                    "".join(
                        line
                        for line in rules.read_text().splitlines(True)
                        if not line.startswith("jitter_ms")
                    )
                )
                got, c2, w2 = check(tree, log, plain)
                return got, cpu + c2, wall + w2
            return None, cpu, wall
        rows: Counter = Counter()  # per (rule, node, COB-ID): rows listed
        total: dict[tuple, int] = {}  # ... and the "(M in all)" of an older tree's tally
        for rec in json.loads(dest.read_text()):
            key = (rec["rule"], rec.get("node"), rec.get("cob_id"))
            more = MORE.search(rec.get("message", ""))
            if more:  # an older tree's JSON sometimes lost listed rows: M is the count
                total[key] = int(more.group(2))
            else:
                rows[key] += 1
        counts: Counter = Counter()
        for key in set(rows) | set(total):
            counts[key[0]] += total.get(key, rows[key])
        return counts, cpu, wall


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="folder of real logs")
    ap.add_argument("--against", type=Path, help="another checkout to compare with")
    ap.add_argument("--out", type=Path, default=HERE / "out" / "precision", help="stack traffic")
    ap.add_argument("--limit", type=int, help="only the first N real logs (smoke test)")
    ap.add_argument("--no-stack", action="store_true", help="leave out the python-canopen traffic")
    args = ap.parse_args(argv)
    if args.against is not None and not (args.against / "cananalyze").is_dir():
        print(f"{args.against}: no cananalyze package there", file=sys.stderr)
        return 2
    sys.path.insert(0, str(ROOT))
    logs: list[tuple[str, Path, Path | None]] = [
        ("real", p, None) for p in real_logs(args.data)[: args.limit]
    ]
    if not args.no_stack:
        logs += [("stack", log, rules) for log, rules in stack_logs(args.out)]
    trees = {"this": ROOT} | ({"other": args.against} if args.against else {})
    totals = {name: {"real": Counter(), "stack": Counter()} for name in trees}
    frames = {"real": 0, "stack": 0}
    cost = {name: [0.0, 0.0] for name in trees}
    head = "".join(f" {name:>7}" for name in trees)
    print(f"{'log':60} {'frames':>9}{head}  (findings)")
    for kind, log, rules in logs:
        n = frames_of(log)
        if not n:
            continue
        got = {}
        for name, tree in trees.items():  # interleaved: the machine's load hits both
            counts, cpu, wall = check(tree, log, rules)
            cost[name][0] += cpu
            cost[name][1] += wall
            got[name] = counts
        if any(c is None for c in got.values()):
            continue  # a log one of the trees cannot read: not comparable
        frames[kind] += n
        for name, counts in got.items():
            totals[name][kind].update(counts)
        label = str(log.relative_to(args.data) if kind == "real" else f"stack/{log.name}")
        cells = "".join(f" {sum(got[name].values()):7d}" for name in trees)
        print(f"{label[-60:]:60} {n:9d}{cells}")
    for kind, title in (("real", "real logs"), ("stack", "python-canopen traffic (no faults)")):
        if not frames[kind]:
            continue
        print(f"\n{title}: {frames[kind]} frames; findings per rule (per 1,000 frames)")
        rules_seen = sorted(set().union(*(totals[name][kind] for name in trees)))
        for rule in rules_seen:
            cells = "".join(
                f" {totals[name][kind][rule]:7d} ({1000 * totals[name][kind][rule] / frames[kind]:7.3f})"
                for name in trees
            )
            print(f"  {rule:22}{cells}")
        cells = "".join(
            f" {sum(totals[name][kind].values()):7d} "
            f"({1000 * sum(totals[name][kind].values()) / frames[kind]:7.3f})"
            for name in trees
        )
        print(f"  {'all':22}{cells}")
    print()
    for name, (cpu, wall) in cost.items():
        print(f"{name}: CPU {cpu:.2f} s, wall {wall:.2f} s ({trees[name]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
