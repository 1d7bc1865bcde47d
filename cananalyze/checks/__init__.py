"""Timing analysis and conformance rules."""
