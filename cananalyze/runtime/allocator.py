"""Process-wide memory settings for a long decode: few page faults, and a peak flat in log length.

Every batch allocates and frees the same few dozen megabytes of arrays. glibc's
malloc hands blocks of this size back to the kernel (munmap, or trimming the
heap top) as soon as they are freed, so the next batch faults every page in
again: at 10M frames that was 130k minor faults and 0.6-1.4 s of system time,
a tenth of the export. Raising the mmap and trim thresholds keeps the memory
mapped between batches (half the faults, a third less system time).

Arrow's buffers (table building, Parquet encoding) go to Arrow's bundled
jemalloc, not to that heap: glibc placed their varying sizes at ever new spots
of its kept heap, so RSS crept while the bytes in use stayed flat (export with
16 devices, 5M vs 50M frames: system pool +13-15 %, jemalloc +4-7 %, same
speed; Arrow's own default here, mimalloc, peaked 30-60 MB higher). Both are
process-wide settings, so only the command line applies them (`tune`), never a
library call from a notebook.
"""

from __future__ import annotations

import os

_M_TRIM_THRESHOLD = -1  # mallopt parameters, from glibc's malloc.h
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD = 32 << 20  # glibc's largest allowed value: batch arrays stay on the heap
TRIM_THRESHOLD = 256 << 20  # free heap kept before it is returned
TOP_PAD = 64 << 20  # heap growth per request: fewer brk calls


def tune() -> bool:
    """Apply the settings; True when glibc's mallopt took them (no-op elsewhere)."""
    # before pyarrow is imported, and only when the user has not chosen a pool
    if arrow_has_jemalloc():
        os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "jemalloc")
    import ctypes  # here: `cananalyze --help` does not need it

    try:
        mallopt = ctypes.CDLL(None).mallopt  # glibc only (not macOS, musl, Windows)
    except (AttributeError, OSError, TypeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
    ok &= mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    ok &= mallopt(_M_TOP_PAD, TOP_PAD)
    return bool(ok)


def arrow_has_jemalloc() -> bool:
    """Whether the installed pyarrow was built with jemalloc, without importing it.

    Naming a pool Arrow lacks prints a warning on every run, and importing
    pyarrow to ask would cost commands that never use it; the build's
    `arrow/util/config.h`, shipped in the wheel, says it in one small read.
    """
    from importlib.util import find_spec

    try:
        spec = find_spec("pyarrow")
    except (ImportError, ValueError):
        return False
    if spec is None or not spec.origin:
        return False
    config = os.path.join(os.path.dirname(spec.origin), "include", "arrow", "util", "config.h")
    try:
        with open(config, encoding="utf-8", errors="replace") as f:
            return any(line.startswith("#define ARROW_JEMALLOC") for line in f)
    except OSError:
        return False
