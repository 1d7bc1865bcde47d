"""cananalyze: CANopen bus traffic analyser and log decoder."""

from __future__ import annotations

from typing import TYPE_CHECKING

__version__ = "0.1.0"

if TYPE_CHECKING:
    from .capture import Capture


def load(path, **options) -> Capture:
    """Decode a log into a Capture of DataFrames; see `cananalyze.capture.load`.

    Imported on call so that `import cananalyze` (and the CLI) stays light.
    """
    from .capture import load as _load

    return _load(path, **options)


__all__ = ["__version__", "load"]
