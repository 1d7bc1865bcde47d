"""Timing analysis and conformance rules (`cananalyze check`)."""
