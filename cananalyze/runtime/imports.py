"""python-can without its MF4 half, in the command line's own process.

When asammdf is installed (the `mf4` extra), `import can` imports it for python-can's
MF4Reader (can/io/mf4.py), and asammdf imports sympy, pandas and numexpr: 0.6-0.7 s of
every command that parses an EDS (canopen imports python-can), ten times what the rest of
python-can costs. cananalyze never uses python-can's MF4 reader (formats/logs/mf4.py reads
MF4 with asammdf itself, importing it only for an MF4 file), so the program hides asammdf
from python-can's import, and only from it. This changes the process, so only the
program applies it (`install`), as with the allocator; a library call never does: in a
notebook python-can keeps its MF4Reader.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys


class _CanWithoutAsammdf(importlib.abc.MetaPathFinder):
    """Finds `can` as usual, and runs its import with `asammdf` unimportable."""

    def find_spec(self, name, path=None, target=None):
        if name != "can":
            return None
        uninstall()  # once: later imports of can are already done
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        loader = getattr(spec, "loader", None)
        if loader is None or not hasattr(loader, "exec_module"):
            return spec
        run = loader.exec_module

        def exec_module(module) -> None:
            hide = "asammdf" not in sys.modules  # mid-import by asammdf itself: leave it
            if hide:
                sys.modules["asammdf"] = None  # `import asammdf` raises ImportError
            try:
                run(module)
            finally:
                if hide and "asammdf" in sys.modules and sys.modules["asammdf"] is None:
                    del sys.modules["asammdf"]

        loader.exec_module = exec_module
        return spec


_FINDER = _CanWithoutAsammdf()


def install() -> None:
    """Hide asammdf from python-can's import, if python-can is not imported yet."""
    if "can" not in sys.modules and _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)


def uninstall() -> None:
    if _FINDER in sys.meta_path:
        sys.meta_path.remove(_FINDER)
