"""Rules and network files (YAML): loading and validation with line-numbered messages.

Only `yaml.safe_load`/`yaml.compose` with the safe loader: user text is data, never code.
The composed node tree gives each value's line for error messages.
"""

from __future__ import annotations

import inspect
from pathlib import Path

import yaml

from ..errors import InputError
from .finding import SEVERITIES
from .registry import ASSERTIONS, RULES
from .rule import Rule

_COMMON = {"enabled", "severity", "tolerance"}


class _Doc:
    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise InputError(f"{path}: cannot read: {exc.strerror}") from None
        try:
            self.root = yaml.compose(text, Loader=yaml.SafeLoader)
            self.data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f":{mark.line + 1}" if mark else ""
            raise InputError(
                f"{path}{where}: not valid YAML: {getattr(exc, 'problem', exc)}"
            ) from None
        if self.data is None:
            self.data = {}
        if not isinstance(self.data, dict):
            self.fail([], "the file must be a mapping (key: value lines)")

    def line(self, keys: list) -> int:
        node = self.root
        line = node.start_mark.line + 1 if node else 1
        for k in keys:
            if isinstance(node, yaml.MappingNode):
                nxt = None
                for kn, vn in node.value:
                    if str(kn.value) == str(k) or _int(kn.value) == k:
                        nxt = vn
                        line = kn.start_mark.line + 1
                        break
                node = nxt
            elif isinstance(node, yaml.SequenceNode) and isinstance(k, int) and k < len(node.value):
                node = node.value[k]
                line = node.start_mark.line + 1
            else:
                break
            if node is None:
                break
        return line

    def fail(self, keys: list, message: str):
        raise InputError(f"{self.path}:{self.line(keys)}: {message}")


def _int(text) -> int | None:
    try:
        return int(str(text), 0)
    except ValueError:
        return None


def _check_params(doc: _Doc, keys: list, cls: type[Rule], params: dict) -> dict:
    sig = inspect.signature(cls.__init__)
    allowed = {p for p in sig.parameters if p not in ("self", "kw")} | _COMMON
    for k, v in params.items():
        if k not in allowed:
            doc.fail(
                keys + [k],
                f"unknown setting {k!r} for {cls.name} (known: {', '.join(sorted(allowed))})",
            )
        if k == "severity" and v not in SEVERITIES:
            doc.fail(keys + [k], f"severity must be one of {', '.join(SEVERITIES)}, not {v!r}")
        if k == "tolerance" and (
            not isinstance(v, (int, float)) or isinstance(v, bool) or not 0 <= v < 10
        ):
            doc.fail(keys + [k], f"tolerance is a fraction like 0.1 (10 %), not {v!r}")
    for name, p in sig.parameters.items():
        if (
            name not in ("self", "kw")
            and p.default is inspect.Parameter.empty
            and p.kind != p.VAR_KEYWORD
            and name not in params
        ):
            doc.fail(keys, f"{cls.name} needs {name!r}")
    return {k: v for k, v in params.items() if k != "enabled"}


def load_rules(path: str | Path) -> tuple[list[Rule], dict | None, Path]:
    """Rules to run (defaults + settings + assertions) and an inline `network:` section, if any."""
    doc = _Doc(Path(path))
    data = doc.data
    for k in data:
        if k not in ("tolerance", "rules", "assert", "network"):
            doc.fail([k], f"unknown top-level key {k!r} (known: tolerance, rules, assert, network)")
    default_tol = data.get("tolerance")
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
        rules.append(_make(doc, keys, cls, kw))
    network = data.get("network")
    if network is not None:
        validate_network(doc, network, ["network"])
    return rules, network, doc.path.parent


def _make(doc: _Doc, keys: list, cls: type[Rule], kw: dict) -> Rule:
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


_NODE_KEYS = {
    "profile",
    "heartbeat_ms",
    "heartbeat_consumer",
    "guard_time_ms",
    "life_time_factor",
    "emcy_inhibit_100us",
}
_PDO_KEYS = {
    "node",
    "direction",
    "number",
    "transmission_type",
    "inhibit_100us",
    "event_timer_ms",
    "length",
}


def validate_network(doc: _Doc, net, keys: list) -> None:
    if not isinstance(net, dict):
        doc.fail(keys, "network must be a mapping with nodes:, sync:, pdos:, known_cob_ids:")
    for k in net:
        if k not in ("nodes", "sync", "pdos", "known_cob_ids"):
            doc.fail(
                keys + [k], f"unknown network key {k!r} (known: nodes, sync, pdos, known_cob_ids)"
            )
    for node, spec in (net.get("nodes") or {}).items():
        if not isinstance(node, int) or not 1 <= node <= 127:
            doc.fail(keys + ["nodes", node], f"node-ID {node!r} must be 1..127")
        for k, v in (spec or {}).items():
            if k not in _NODE_KEYS:
                doc.fail(
                    keys + ["nodes", node, k],
                    f"unknown node setting {k!r} (known: {', '.join(sorted(_NODE_KEYS))})",
                )
            if k not in ("profile", "heartbeat_consumer") and (
                not isinstance(v, (int, float)) or v < 0
            ):
                doc.fail(keys + ["nodes", node, k], f"{k} must be a non-negative number, not {v!r}")
    for k, v in (net.get("sync") or {}).items():
        if k not in ("period_us", "window_us") or not isinstance(v, (int, float)):
            doc.fail(keys + ["sync", k], "sync: takes period_us and window_us (numbers)")
    for cob, spec in (net.get("pdos") or {}).items():
        if not isinstance(cob, int) or not 0 < cob < 0x800:
            doc.fail(
                keys + ["pdos", cob], f"PDO COB-ID {cob!r} must be an 11-bit identifier like 0x285"
            )
        if not isinstance(spec, dict) or "node" not in spec:
            doc.fail(keys + ["pdos", cob], "each PDO needs at least node:")
        for k in spec:
            if k not in _PDO_KEYS:
                doc.fail(
                    keys + ["pdos", cob, k],
                    f"unknown PDO setting {k!r} (known: {', '.join(sorted(_PDO_KEYS))})",
                )


def load_network(path: str | Path) -> tuple[dict, Path]:
    doc = _Doc(Path(path))
    validate_network(doc, doc.data, [])
    return doc.data, doc.path.parent
