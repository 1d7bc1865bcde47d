"""cananalyze: CANopen bus traffic analyser and log decoder."""

__version__ = "0.1.0"
