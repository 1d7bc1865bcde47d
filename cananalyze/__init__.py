"""cananalyze: CANopen bus traffic analyser and log decoder.

    cap = cananalyze.load("run.blf", network="net.toml")     # the decoded log as DataFrames
    found = cananalyze.check("run.blf", rules="rules.yaml")  # the findings of `cananalyze check`

Both run the one pipeline (`cananalyze.pipeline`) that every command runs. The names
below are imported on first use, so `import cananalyze` (and the CLI) stays light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from cananalyze.core.version import __version__

if TYPE_CHECKING:
    from cananalyze.api.capture import Capture
    from cananalyze.core.finding import Finding

# public name -> module that defines it
_LAZY = {
    "Capture": "api.capture",
    "Finding": "core.finding",
    "FrameBatch": "core.frames",
    "DecodedBatch": "core.records",
    "Options": "pipeline",
    "Run": "pipeline",
    "build_decoder": "pipeline",
    "open_source": "pipeline",
    "run": "pipeline",
    "Sink": "pipeline.sink",
    "CananalyzeError": "core.errors",
    "InputError": "core.errors",
    "UsageError": "core.errors",
}


def load(path, **options) -> Capture:
    """Decode and check a log into a Capture of DataFrames; see `cananalyze.api.capture.load`."""
    from cananalyze.api.capture import load as _load

    return _load(path, **options)


def check(path, **options) -> list[Finding]:
    """The findings `cananalyze check` reports for a log; see `cananalyze.api.capture.check`."""
    from cananalyze.api.capture import check as _check

    return _check(path, **options)


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'cananalyze' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f"{__name__}.{module}"), name)


__all__ = ["__version__", "check", "load", *_LAZY]
