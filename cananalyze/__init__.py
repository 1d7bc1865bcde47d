"""cananalyze: CANopen bus traffic analyser and log decoder.

    cap = cananalyze.load("run.blf", network="net.toml")     # the decoded log as DataFrames
    found = cananalyze.check("run.blf", rules="rules.yaml")  # the findings of `cananalyze check`

Both run the one pipeline (`cananalyze.pipeline`) that every command runs. The names
below are imported on first use, so `import cananalyze` (and the CLI) stays light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

__version__ = "0.1.0"

if TYPE_CHECKING:
    from cananalyze.capture import Capture
    from cananalyze.checks.finding import Finding

# public name -> module that defines it
_LAZY = {
    "Capture": "capture",
    "Finding": "checks.finding",
    "FrameBatch": "frames",
    "DecodedBatch": "records",
    "Options": "pipeline",
    "Run": "pipeline",
    "build_decoder": "pipeline",
    "open_source": "pipeline",
    "run": "pipeline",
    "Sink": "outputs.sink",
    "CananalyzeError": "errors",
    "InputError": "errors",
    "UsageError": "errors",
}


def load(path, **options) -> Capture:
    """Decode and check a log into a Capture of DataFrames; see `cananalyze.capture.load`."""
    from cananalyze.capture import load as _load

    return _load(path, **options)


def check(path, **options) -> list[Finding]:
    """The findings `cananalyze check` reports for a log, in time order (rules and network
    as keyword arguments, like `load()`); `[f for f in found if f.fails]` are violations."""
    from cananalyze.capture import load_options
    from cananalyze.outputs.findings import FindingsSink
    from cananalyze.pipeline import build_checker, build_decoder, open_source, run

    opts = load_options(**options)
    checker = build_checker(opts)
    report = FindingsSink(quiet=True)
    run(open_source(path, opts), build_decoder(opts, checker), [report], opts)
    return report.findings.findings()  # Finding objects: what a Python caller reads


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'cananalyze' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(f"{__name__}.{module}"), name)


__all__ = ["__version__", "check", "load", *_LAZY]
