"""Build a Checker from a rules file and a network file (shared by the CLI and assertions)."""

from __future__ import annotations

from pathlib import Path

from .config import FileConfig
from .engine import Checker
from .rule import Rule


def build_checker(
    rules_file: str | Path | None = None,
    network_file: str | Path | None = None,
    rules: list[Rule] | None = None,
) -> Checker:
    from .rulesfile import load_network, load_rules

    network, base = None, None
    if rules_file:
        loaded, network, base = load_rules(rules_file)
        rules = (rules or []) + loaded
    if network_file:
        network, base = load_network(network_file)
    return Checker(rules, FileConfig(network, base))


def attach_checker(decoder, rules: Checker | str | Path | None = None) -> Checker:
    """Append a Checker (or the rules file's) to a decoder built by `cli.pipeline.build_decoder`.

    The one place `check`, `live --check` and `cananalyze.load(..., rules=...)` get their
    Checker from, so the CLI and the Python API find the same things. When the decoder
    has a network model, the Checker reads configuration through it (SDO writes seen in
    the log, the network file), see `model_config`. Pass a built Checker to have a bad
    rules file rejected before the log is opened.
    """
    from ..network.model import NetworkModel
    from .model_config import ModelConfig

    checker = rules if isinstance(rules, Checker) else build_checker(rules)
    model = next((p for p in decoder.processors if isinstance(p, NetworkModel)), None)
    if model is not None:
        checker.config = ModelConfig(model, checker.config)
    decoder.processors.append(checker)
    return checker
