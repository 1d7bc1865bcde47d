"""Long fuzz campaign (issue 24): every reader, the configuration and EDS loaders, exports.

    nice -n 10 python benchmarks/fuzz_campaign.py --seconds 1200 --seed 1

Each case runs in a forked child under a memory limit (RLIMIT_AS, --memory MB) and a
CPU-time limit (RLIMIT_CPU, --timeout s; ten times that in wall time for a sleeping
child), so a blow-up or a hang is counted, not suffered, whatever the machine's load. Kinds of case:

- log: a real log (../shared/data/real, samples/) mutated byte- or token-wise, read by
  tests.fuzz.harness.run_log (reader, decoder, text/JSONL writers, summary);
- junk: good candump frames with junk lines between them: every good frame must be kept;
- config: network YAML/TOML and rules files mutated, plus hostile shapes (alias bombs,
  deep nesting, huge files), through the one reader;
- eds: an EDS mutated, through canopen's import (read_od);
- xdd: an XDD (tests/data/xdd) mutated byte- or token-wise, or a hostile XML shape
  (entity expansion, external entity, deep nesting, a huge attribute), through the XDD
  reader and the device profile built from it, as .xdd, .xdc or .eds (content decides);
- export: a mutated log exported to Parquet, CSV and MCAP: no hidden file may remain.

Prints counts per category: cases, crashes, hangs, memory blow-ups, lost frames,
leftover files; the first input of each distinct failure is saved to --out.
"""

from __future__ import annotations

import argparse
import atexit
import os
import random
import resource
import select
import shutil
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# The command line's allocator (runtime.allocator), set before pyarrow is imported: Arrow's
# default pool, mimalloc, reserves 1 GiB of address space on first use (pyarrow 26: VmSize
# +1,050 MB on the first cast), which RLIMIT_AS counts as if it were memory; every log case's
# first Arrow allocation then failed in the child, though the case needs a few MB.
from cananalyze.runtime import allocator  # noqa: E402

allocator.tune()

from tests.fuzz import targets  # noqa: E402
from tests.fuzz.campaign import _logs, _suffix, mutate_bytes, mutate_tokens  # noqa: E402
from tests.fuzz.harness import run_log  # noqa: E402

KINDS = ["log", "log", "log", "junk", "config", "eds", "xdd", "export"]
HOSTILE_CONFIG = [
    b"a0: &a0 [x, x, x, x, x, x, x, x, x]\n"
    + b"".join(f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]\n".encode() for i in range(1, 10)),
    b"nodes: &a {3: *a}\n",
    b"[" * 50_000 + b"]" * 50_000,
    b"a = " + b"[" * 50_000 + b"]" * 50_000,
    b"nodes:\n  3: {name: \xff}\n",
    b"x: " + b"9" * 100_000 + b"\n",
    b"nodes: {3: {heartbeat_ms: 1e999}}\n",
    b"network: {nodes: [1, 2]}\n",
]


def _case(kind: str, rng: random.Random, logs, cache) -> tuple[str, bytes, str]:
    """(what, input bytes, suffix) for one case; `what` says which target runs it."""
    if kind == "log":
        p = rng.choice(logs)
        data = cache[p]
        if len(data) > 200_000 and p.suffix != ".blf":
            s = rng.randrange(len(data) - 100_000)
            data = data[:2000] + data[s : s + 60_000]
        texts = p.suffix not in (".blf", ".gz", ".mcap")
        blob = mutate_tokens(rng, data) if texts and rng.random() < 0.3 else mutate_bytes(rng, data)
        suffix = (
            rng.choice([".log", ".asc", ".blf", ".trc", ".csv", ".txt", ".mcap", ""])
            if rng.random() < 0.2
            else _suffix(p)
        )
        return "log", blob, suffix
    if kind == "junk":
        blob, n = targets.junk_mixed(rng, rng.randint(1, 400))
        return f"junk:{n}", blob, ".log"
    if kind == "config":
        which = rng.choice(["network.yaml", "network.toml", "rules.yaml"])
        good = {"network.yaml": targets.GOOD_NETWORK, "network.toml": targets.GOOD_TOML}.get(
            which, targets.GOOD_RULES
        )
        blob = rng.choice(HOSTILE_CONFIG) if rng.random() < 0.15 else mutate_bytes(rng, good)
        return f"config:{which}", blob, ""
    if kind == "eds":
        return "eds", mutate_bytes(rng, targets.GOOD_EDS), rng.choice([".eds", ".dcf"])
    if kind == "xdd":
        suffix = rng.choice([".xdd", ".xdc", ".eds"])
        if rng.random() < 0.1:
            return "xdd", rng.choice(targets.HOSTILE_XML), suffix
        seed = cache.setdefault(p := rng.choice(targets.XDD_SEEDS), p.read_bytes())
        pick = rng.random()
        if pick < 0.6:  # well-formed: the reader's meaning, not only the XML parser
            blob = targets.mutate_xml(rng, seed)
        else:
            blob = mutate_tokens(rng, seed) if pick < 0.7 else mutate_bytes(rng, seed)
        return "xdd", blob, suffix
    p = rng.choice([q for q in logs if q.stat().st_size < 300_000])
    return "export", mutate_bytes(rng, cache[p]), _suffix(p)


def _run(what: str, blob: bytes, suffix: str) -> str:
    """In the child: '' when fine, else the failure category and a short reason."""
    if what == "log":
        run_log(blob, suffix, strict=random.random() < 0.3)
    elif what.startswith("junk:"):
        want = int(what[5:])
        got = targets.kept_frames(blob)
        if got != want:
            return f"lost frames {got} of {want}"
    elif what.startswith("config:"):
        targets.load_config(blob, what[7:])
    elif what == "eds":
        targets.load_eds(blob, suffix)
    elif what == "xdd":
        targets.load_xdd(blob, suffix)
    else:
        with tempfile.TemporaryDirectory() as out:
            left = targets.export_leaves_nothing(blob, suffix, Path(out))
            if left:
                return f"leftover files {left}"
    return ""


def _fork(what: str, blob: bytes, suffix: str, memory_mb: int, timeout: float) -> tuple[str, str]:
    """(category, detail): category '' (fine), crash, hang, memory, lost, leftover."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        os.close(r)
        code = 0
        try:
            # on top of what the process already maps (numpy, pyarrow and canopen loaded)
            limit = (memory_mb << 20) + _mapped()
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
            # CPU seconds, not wall: a loaded shared machine must not turn slow into "hang"
            cpu = int(timeout) + int(_cpu_self())
            resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 5))
            bad = _run(what, blob, suffix)
            msg = (("lost" if bad.startswith("lost") else "leftover") + "\t" + bad) if bad else ""
        except MemoryError:
            msg = "memory\tMemoryError"
        except BaseException as exc:  # noqa: BLE001 - the point is to catch everything
            tb = traceback.extract_tb(exc.__traceback__)
            where = next((f for f in reversed(tb) if "cananalyze/" in f.filename), tb[-1])
            msg = f"crash\t{type(exc).__name__} at {where.filename.split('cananalyze/')[-1]}:{where.lineno}"
        os.write(w, msg.encode()[:4000])
        os.close(w)
        os._exit(code)
    os.close(w)
    ready = select.select([r], [], [], timeout * 10)[0]  # wall: a last resort (sleeps)
    if not ready:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        os.close(r)
        return "hang", f"over {timeout * 10:g} s wall"
    out = b""
    while chunk := os.read(r, 4096):
        out += chunk
    os.close(r)
    _, status = os.waitpid(pid, 0)
    if not out and os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGXCPU:
        return "hang", f"over {timeout:g} s CPU"
    if not out and os.WIFSIGNALED(status):
        return "memory" if os.WTERMSIG(status) in (signal.SIGKILL, signal.SIGSEGV) else "crash", (
            f"killed by signal {os.WTERMSIG(status)}"
        )
    cat, _, detail = out.decode(errors="replace").partition("\t")
    return cat, detail


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--memory", type=int, default=1024, help="MB per case (RLIMIT_AS)")
    ap.add_argument("--timeout", type=float, default=20, help="CPU seconds per case")
    ap.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "cananalyze-fuzz"))
    ap.add_argument(
        "--kind",
        action="append",
        choices=sorted(set(KINDS)),
        help="only these kinds of case (repeatable; default all, logs weighted 3)",
    )
    a = ap.parse_args(argv)
    if "CANANALYZE_CACHE" not in os.environ:  # the device files' facts: not the user's cache
        os.environ["CANANALYZE_CACHE"] = tempfile.mkdtemp(prefix="cananalyze-fuzz-cache-")
        atexit.register(shutil.rmtree, os.environ["CANANALYZE_CACHE"], True)
    kinds = a.kind or KINDS
    rng = random.Random(a.seed)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    logs = _logs()
    cache = {p: p.read_bytes() for p in logs}
    _warm()
    cases: Counter = Counter()
    fails: Counter = Counter()
    distinct: dict[tuple[str, str], int] = {}
    cpu0, t0 = _cpu(), time.time()
    while time.time() - t0 < a.seconds:
        kind = rng.choice(kinds)
        what, blob, suffix = _case(kind, rng, logs, cache)
        cases[kind] += 1
        cat, detail = _fork(what, blob, suffix, a.memory, a.timeout)
        if not cat:
            continue
        fails[(kind, cat)] += 1
        key = (cat, detail if cat in ("crash", "memory") else f"{kind}:{detail[:40]}")
        if key not in distinct:
            distinct[key] = len(distinct) + 1
            (out / f"{cat}_{distinct[key]}_{kind}{suffix or '.bin'}").write_bytes(blob)
        distinct.setdefault(key, 0)
    wall, cpu = time.time() - t0, _cpu() - cpu0
    print(f"fuzz campaign: seed {a.seed}, {wall:.0f} s wall, {cpu:.0f} s CPU (user+sys, children)")
    cats = ["crash", "hang", "memory", "lost", "leftover"]
    print(f"{'kind':8s} {'cases':>7s} " + " ".join(f"{c:>9s}" for c in cats))
    for kind in sorted(cases):
        print(f"{kind:8s} {cases[kind]:7d} " + " ".join(f"{fails[(kind, c)]:9d}" for c in cats))
    total = sum(cases.values())
    print(
        f"{'total':8s} {total:7d} "
        + " ".join(f"{sum(v for (k, c), v in fails.items() if c == cat):9d}" for cat in cats)
    )
    print(f"distinct failures: {len(distinct)} (inputs in {out})")
    for (cat, detail), n in sorted(distinct.items(), key=lambda kv: kv[1]):
        print(f"  #{n} {cat}: {detail}")
    return 1 if distinct else 0  # .ci/run's short run fails on any


def _warm() -> None:
    """Import once in the parent what the children use (no threads started: a fork must
    not copy a lock another thread holds)."""
    import can.io.asc  # noqa: F401
    import canopen.objectdictionary  # noqa: F401
    import mcap.reader  # noqa: F401
    import pyarrow.csv  # noqa: F401
    import pyarrow.parquet  # noqa: F401
    import yaml  # noqa: F401

    import cananalyze.checks.rulesfile  # noqa: F401
    import cananalyze.devices.profile  # noqa: F401
    import cananalyze.devices.xdd  # noqa: F401
    import cananalyze.outputs.mcap.sink  # noqa: F401
    import cananalyze.outputs.tables.stream  # noqa: F401
    import cananalyze.pipeline  # noqa: F401


def _cpu_self() -> float:
    me = resource.getrusage(resource.RUSAGE_SELF)
    return me.ru_utime + me.ru_stime


def _mapped() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


def _cpu() -> float:
    me, kids = (
        resource.getrusage(resource.RUSAGE_SELF),
        resource.getrusage(resource.RUSAGE_CHILDREN),
    )
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


if __name__ == "__main__":
    sys.exit(main())
