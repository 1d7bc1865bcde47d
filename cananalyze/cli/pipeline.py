"""Builds the Decoder with the processors the command-line options ask for."""

from __future__ import annotations

import argparse

from ..decoder import Decoder
from ..sdo.processor import SdoProcessor
from ..sdo.tracker import SdoTracker


def build_decoder(args: argparse.Namespace) -> Decoder:
    """Processor order matters: SDO transactions first (the network model reads them)."""
    timeout = getattr(args, "sdo_timeout", 1.0)
    processors: list = [SdoProcessor(SdoTracker(timeout=timeout))]
    return Decoder(processors)
