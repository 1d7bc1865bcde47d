"""Where a command's peak memory comes from: RSS against what malloc holds in use, over time.

    python benchmarks/mem_profile.py export LOG --parquet DIR --device 1=dat7014 -q

Runs the cananalyze command in this process and samples, every `--every` seconds:
RSS (anonymous and file-backed), the bytes glibc malloc has handed out and not
freed (`mallinfo2`, glibc 2.33+; blank elsewhere) and the bytes Arrow's pool
holds. When RSS climbs while malloc's in-use bytes stay flat, the growth is the
allocator keeping freed memory (fragmentation), not data the program holds;
when in-use climbs too, something is being kept (a buffer, a cache, a queue).
This is how the row-group buffers of issue 10 were found.
"""

from __future__ import annotations

import ctypes
import sys
import threading
import time

EVERY = 0.05


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        )
    ]


def _mallinfo():
    try:
        f = ctypes.CDLL(None).mallinfo2
    except (AttributeError, OSError, TypeError):
        return None
    f.restype = _MallInfo2
    return f


def _rss() -> tuple[int, int, int]:
    got = {}
    with open("/proc/self/status") as f:
        for line in f:
            key = line.split(":", 1)[0]
            if key in ("VmRSS", "RssAnon", "RssFile"):
                got[key] = int(line.split()[1]) >> 10
    return got.get("VmRSS", 0), got.get("RssAnon", 0), got.get("RssFile", 0)


def _arrow_mb() -> int | None:
    """MB in Arrow's pool, None until pyarrow is imported: never imported here (the CLI
    picks the pool), and read only once whole (the sampler may run mid-import, when
    the module exists without its functions)."""
    allocated = getattr(sys.modules.get("pyarrow"), "total_allocated_bytes", None)
    return allocated() >> 20 if allocated is not None else None


def main(argv: list[str]) -> int:
    every = EVERY
    if argv[:1] == ["--every"]:
        every, argv = float(argv[1]), argv[2:]
    mallinfo = _mallinfo()
    samples: list[tuple] = []
    t0 = time.perf_counter()

    def sample() -> None:
        while True:
            inuse = None
            if mallinfo is not None:
                m = mallinfo()
                inuse = (m.uordblks + m.hblkhd) >> 20
            samples.append((time.perf_counter() - t0, *_rss(), inuse, _arrow_mb()))
            time.sleep(every)

    threading.Thread(target=sample, daemon=True).start()
    from cananalyze.cli.main import main as cli

    try:
        rc = cli(argv)
    finally:
        _report(samples)
    return int(rc or 0)


def _report(samples: list[tuple]) -> None:
    if not samples:
        return
    print("   t s   RSS  anon  file  malloc-in-use  arrow  (MB)", file=sys.stderr)
    step = max(1, len(samples) // 40)
    for t, rss, anon, file, inuse, arrow in samples[::step]:
        print(
            f"{t:6.2f} {rss:5d} {anon:5d} {file:5d} {inuse if inuse is not None else '':>14} "
            f"{arrow if arrow is not None else '':>6}",
            file=sys.stderr,
        )
    peak = max(samples, key=lambda s: s[1])
    inuse = sorted(s[4] for s in samples if s[4] is not None)
    line = f"peak RSS {peak[1]} MB at {peak[0]:.2f} s"
    if inuse:
        line += f"; malloc in use: max {inuse[-1]} MB, median {inuse[len(inuse) // 2]} MB"
    print(line, file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
