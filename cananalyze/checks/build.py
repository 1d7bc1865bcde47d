"""Build a Checker from a rules file (shared by the pipeline, the CLI and the assertions)."""

from __future__ import annotations

from pathlib import Path

from cananalyze.checks.engine import Checker
from cananalyze.checks.rule import Rule


def build_checker(rules_file: str | Path | None = None, rules: list[Rule] | None = None) -> Checker:
    """The default rules plus the rules file's settings and assertions.

    Until a pipeline binds it to the network model that follows the log, the checker
    reads what the rules file's `network:` section declares (unknown otherwise).
    """
    from cananalyze.checks.model_config import ModelConfig
    from cananalyze.checks.rulesfile import read_rules
    from cananalyze.config.netfile import combine
    from cananalyze.decode.model import NetworkModel

    config = network = None
    if rules_file:
        loaded, network = read_rules(rules_file)
        rules = (rules or []) + loaded
        if network is not None:
            config = ModelConfig(NetworkModel(combine(network, source=str(rules_file))))
    checker = Checker(rules, config)
    if rules_file:
        checker.rules_file = (str(rules_file), network)
    return checker
