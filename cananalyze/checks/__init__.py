"""Timing analysis and conformance rules (`cananalyze check`)."""

from .config import ConfigSource
from .engine import Checker
from .finding import Finding

__all__ = ["Checker", "ConfigSource", "Finding"]
