"""The optional compiled helper (`_speedups.c`), or None: callers keep a pure-Python path.

The extension is built by `pip install` when a C compiler is there and skipped
when not; `CANANALYZE_PURE=1` in the environment ignores it even when built (the
tests use it to compare both paths, and it is a way out should the C code ever
disagree with the Python code).
"""

from __future__ import annotations

import os
from types import ModuleType


def _load() -> ModuleType | None:
    if os.environ.get("CANANALYZE_PURE", "") not in ("", "0"):
        return None
    try:
        from . import _speedups
    except ImportError:
        return None
    return _speedups


C: ModuleType | None = _load()
