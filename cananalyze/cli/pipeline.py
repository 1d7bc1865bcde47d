"""Builds the Decoder with the processors the command-line options ask for."""

from __future__ import annotations

import argparse

from ..decoder import Decoder


def build_decoder(args: argparse.Namespace) -> Decoder:
    processors: list = []
    return Decoder(processors)
