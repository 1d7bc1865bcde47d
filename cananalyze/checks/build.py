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
