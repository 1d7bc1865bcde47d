"""The optional compiled helper (`_speedups.c`), or None: callers keep a pure-Python path.

The extension is built by `pip install` when a C compiler is there and skipped
when not (setup.py says so in one line); `CANANALYZE_PURE=1` in the environment
ignores it even when built (CI runs the tests both ways, and it is a way out
should the C code ever disagree with the Python code). `status()` says which path
is in use: `cananalyze --version` prints it.
"""

from __future__ import annotations

import os
from types import ModuleType

_OFF = "pure-Python path: CANANALYZE_PURE is set"
_MISSING = "pure-Python path: compiled helper not built"
_ON = "compiled helper in use"


def _load() -> tuple[ModuleType | None, str]:
    if os.environ.get("CANANALYZE_PURE", "") not in ("", "0"):
        return None, _OFF
    try:
        from cananalyze.runtime import _speedups
    except ImportError:
        return None, _MISSING
    return _speedups, _ON


C, _why = _load()


def status() -> str:
    """One line: whether the compiled helper is in use, and if not, why not."""
    if C is not None:
        return _ON
    return _why if _why != _ON else "pure-Python path"
