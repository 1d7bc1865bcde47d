"""Timing analysis and conformance rules (`cananalyze check`)."""

from cananalyze.checks.config import ConfigSource
from cananalyze.checks.engine import Checker
from cananalyze.core.finding import Finding

__all__ = ["Checker", "ConfigSource", "Finding"]
