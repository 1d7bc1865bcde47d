"""Rules files (YAML): loading and validation with line-numbered messages.

Read through network.filelines (the safe loader only: user text is data, never
code). The `network:` section is a network description in the network file's
schema, read by network.netfile like a `--network` file.
"""

from __future__ import annotations

import functools
import inspect
from pathlib import Path

from cananalyze.checks.registry import ASSERTIONS, RULES
from cananalyze.checks.rule import Rule
from cananalyze.config.filelines import read_tree
from cananalyze.config.netfile import combine, read_network
from cananalyze.config.spec import NetworkSpec
from cananalyze.core.errors import InputError
from cananalyze.core.finding import SEVERITIES
from cananalyze.core.text import printable

_COMMON = {"enabled", "severity", "tolerance", "jitter_ms"}


class _Doc:
    """A rules file's data and lines, for `FILE:LINE: message` errors."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.data, self.lines = read_tree(path, "rules file")
        if self.data is None:
            self.data = {}
        if not isinstance(self.data, dict):
            self.fail([], "the file must be a mapping (key: value lines)")

    def fail(self, keys: list, message: str):
        raise InputError(f"{self.lines.at(tuple(keys))}: {message}")


@functools.cache
def _signature(cls: type[Rule]) -> tuple[inspect.Signature, frozenset[str]]:
    """A rule class's constructor and the settings it takes (asked once per class, not
    once per assertion: a rules file may hold 50,000)."""
    sig = inspect.signature(cls.__init__)
    return sig, frozenset({p for p in sig.parameters if p not in ("self", "kw")} | _COMMON)


def _check_params(doc: _Doc, keys: list, cls: type[Rule], params: dict) -> dict:
    sig, allowed = _signature(cls)
    for k, v in params.items():
        if k not in allowed:
            doc.fail(
                keys + [k],
                f"unknown setting {k!r} for {cls.name} (known: {', '.join(sorted(allowed))})",
            )
        if k == "severity" and v not in SEVERITIES:
            doc.fail(keys + [k], f"severity must be one of {', '.join(SEVERITIES)}, not {v!r}")
        if k == "tolerance":
            _tolerance(doc, keys + [k], v)
        if k == "jitter_ms" and (
            not isinstance(v, (int, float)) or isinstance(v, bool) or not 0 <= v <= 60_000
        ):
            doc.fail(keys + [k], f"jitter_ms is a time in ms like 2 (0..60000), not {v!r}")
        hint = str(getattr(sig.parameters.get(k), "annotation", ""))
        if k not in ("tolerance", "jitter_ms") and ("float" in hint or hint == "int"):
            params[k] = _number(doc, keys + [k], v, sig.parameters[k].default, hint == "int")
    for name, p in sig.parameters.items():
        if (
            name not in ("self", "kw")
            and p.default is inspect.Parameter.empty
            and p.kind != p.VAR_KEYWORD
            and name not in params
        ):
            doc.fail(keys, f"{cls.name} needs {name!r}")
    return {k: v for k, v in params.items() if k != "enabled"}


def _tolerance(doc: _Doc, keys: list, v) -> None:
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not 0 <= v < 10:
        doc.fail(keys, f"tolerance is a fraction like 0.1 (10 %), not {v!r}")


def _number(doc: _Doc, keys: list, value, default, integral: bool) -> float | int:
    """A numeric setting as a number. YAML reads `1e3` (no dot) as text; such text is taken
    as the number it spells, but a value that is not finite (`1e999`) or not a number is an
    error with its line, not a string or infinity reaching the checks' arithmetic."""
    import math

    if isinstance(value, str):
        try:
            value = int(value, 0) if integral else float(value)
        except ValueError:
            doc.fail(keys, f"{keys[-1]}: expected a number, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        doc.fail(keys, f"{keys[-1]}: expected a number, got {value!r}")
    if integral and not float(value).is_integer():
        doc.fail(keys, f"{keys[-1]}: expected an integer, got {value!r}")
    unbounded = isinstance(default, float) and math.isinf(default) and value == default
    if not math.isfinite(value) and not unbounded:
        doc.fail(keys, f"{keys[-1]}: {value!r} is not a finite number")
    return int(value) if integral else value


def load_rules(path: str | Path) -> tuple[list[Rule], NetworkSpec | None]:
    """Rules to run (defaults + settings + assertions) and what the `network:` section
    declares, if there is one (checked here, so a bad value fails before the log is read)."""
    rules, network = read_rules(path)
    return rules, None if network is None else combine(network, source=str(path))


def read_rules(path: str | Path) -> tuple[list[Rule], dict | None]:
    """`load_rules`, with the `network:` section as its checked settings (netfile.combine's
    input, as `rules_network` gives them), from one reading of the file: a pipeline takes
    both from here (checks/build.py) instead of parsing the file again."""
    doc = _Doc(Path(path))
    data = doc.data
    for k in data:
        if k not in ("tolerance", "jitter_ms", "rules", "assert", "network"):
            doc.fail(
                [k],
                f"unknown top-level key {k!r} (known: tolerance, jitter_ms, rules, assert, network)",
            )
    default_tol = data.get("tolerance")
    default_jitter = data.get("jitter_ms")
    if default_tol is not None or default_jitter is not None:
        _check_params(
            doc,
            [],
            RULES["heartbeat"],
            {k: data[k] for k in ("tolerance", "jitter_ms") if k in data},
        )
    settings = data.get("rules") or {}
    if not isinstance(settings, dict):
        doc.fail(["rules"], "rules: must map rule names to settings")
    rules: list[Rule] = []
    for name in settings:
        if name not in RULES:
            doc.fail(["rules", name], f"unknown rule {name!r} (known: {', '.join(RULES)})")
    for name, cls in RULES.items():
        params = settings.get(name)
        if params is None:
            params = {}
        elif params is False or params is True:
            params = {"enabled": params}
        elif not isinstance(params, dict):
            doc.fail(["rules", name], f"{name}: give a mapping of settings or true/false")
        if params.get("enabled", True) is False:
            continue
        kw = _check_params(doc, ["rules", name], cls, params)
        if default_tol is not None:
            kw.setdefault("tolerance", default_tol)
        if default_jitter is not None:
            kw.setdefault("jitter_ms", default_jitter)
        rules.append(_make(doc, ["rules", name], cls, kw))
    asserts = data.get("assert") or []
    if not isinstance(asserts, list):
        doc.fail(["assert"], "assert: must be a list of '- kind: {settings}' items")
    for i, item in enumerate(asserts):
        if not isinstance(item, dict) or len(item) != 1:
            doc.fail(["assert", i], "each assertion is one 'kind: {settings}' mapping")
        ((kind, params),) = item.items()
        keys = ["assert", i, kind]
        if kind == "no_emcy":
            _replace(
                rules,
                "emcy",
                _make(
                    doc,
                    keys,
                    RULES["emcy"],
                    _check_params(
                        doc, keys, RULES["emcy"], {"allow": (params or {}).get("except", [])}
                    ),
                ),
            )
            continue
        if kind == "sdo":
            p = dict(params or {})
            p.pop("success", None)
            _replace(
                rules,
                "sdo",
                _make(doc, keys, RULES["sdo"], _check_params(doc, keys, RULES["sdo"], p)),
            )
            continue
        if kind == "error_frames":
            _replace(
                rules,
                "error_frames",
                _make(
                    doc,
                    keys,
                    RULES["error_frames"],
                    _check_params(doc, keys, RULES["error_frames"], params or {}),
                ),
            )
            continue
        cls = ASSERTIONS.get(kind)
        if cls is None:
            known = ", ".join(list(ASSERTIONS) + ["no_emcy", "sdo", "error_frames"])
            doc.fail(["assert", i], f"unknown assertion {kind!r} (known: {known})")
        if not isinstance(params, dict):
            doc.fail(keys, f"{kind}: give its settings as a mapping")
        kw = _check_params(doc, keys, cls, params)
        if default_tol is not None:
            kw.setdefault("tolerance", default_tol)
        if default_jitter is not None:
            kw.setdefault("jitter_ms", default_jitter)
        rules.append(_make(doc, keys, cls, kw))
    return rules, _network(doc)


def _make(doc: _Doc, keys: list, cls: type[Rule], kw: dict) -> Rule:
    # the file's texts (a signal's, a node's name) as a terminal may show them, and as the
    # decoded names are (`core.text.printable`): a signal named with a control character
    # in the network file and here is still one signal
    kw = {k: printable(v) if isinstance(v, str) else v for k, v in kw.items()}
    try:
        return cls(**kw)
    except (TypeError, ValueError) as exc:
        doc.fail(keys, f"{cls.name}: {exc}")


def _replace(rules: list[Rule], name: str, new: Rule) -> None:
    for i, r in enumerate(rules):
        if r.name == name:
            rules[i] = new
            return
    rules.append(new)


def _network(doc: _Doc) -> dict | None:
    if "network" not in doc.data:
        return None
    return read_network(
        doc.data["network"], doc.lines.under("network"), doc.path.parent, "rules file"
    )


def rules_network(path: str | Path) -> dict | None:
    """The checked settings of a rules file's `network:` section (netfile.combine's input),
    or None when it has none."""
    return _network(_Doc(Path(path)))
