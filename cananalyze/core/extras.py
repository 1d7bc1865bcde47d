"""Optional features and the one message a command gives when its extra is not installed.

A plain `pip install cananalyze` decodes, checks, exports and reports; the fleet (Dask,
its dashboard, DuckDB) and the live Foxglove server are extras (pyproject.toml), so
their packages are imported only where used, through `need`: a missing one is one line
naming the extra (the CLI's `cananalyze: error: ...`, exit 2), not a traceback.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from cananalyze.core.errors import UsageError


class MissingExtra(UsageError):
    """A feature whose optional package is not installed; the message names the extra."""

    def __init__(self, feature: str, extra: str, module: str) -> None:
        self.feature, self.extra, self.module = feature, extra, module
        super().__init__(
            f"{feature} needs the {extra} extra ({module} is not installed): "
            f'pip install "cananalyze[{extra}]"'
        )


def need(module: str, feature: str, extra: str) -> ModuleType:
    """`module` imported for `feature`, or MissingExtra naming the extra that installs it.

    Only a module that cannot be found counts as missing: any other import error is a
    broken install and keeps its traceback.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        raise MissingExtra(feature, extra, exc.name or module) from None


def need_installed(module: str, feature: str, extra: str) -> None:
    """As `need`, without importing `module` (found by its spec): for a command that may
    end before it uses it (a fleet rerun with nothing to decode starts no cluster)."""
    import importlib.util

    try:
        found = importlib.util.find_spec(module) is not None
    except ModuleNotFoundError as exc:
        raise MissingExtra(feature, extra, exc.name or module) from None
    if not found:
        raise MissingExtra(feature, extra, module)
