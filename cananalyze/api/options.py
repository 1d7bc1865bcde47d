"""The keyword arguments of `load()`, `check()` and the assertions as pipeline Options."""

from __future__ import annotations

from pathlib import Path

from cananalyze.core.defaults import SDO_TIMEOUT


def load_options(
    network=None,
    eds=None,
    device=None,
    strict: bool = False,
    input_format: str | None = None,
    sdo_timeout: float = SDO_TIMEOUT,
    rules=None,
    **more,
):
    """Options from `load()`'s keyword arguments: devices and EDS files as {node: value}
    or as the command line's ["NODE=VALUE", ...]."""
    from cananalyze.pipeline import Options

    return Options(
        network=network,
        devices=_by_node(device, "device"),
        eds=_by_node(eds, "eds"),
        rules=rules,
        checks=True,
        strict=strict,
        input_format=input_format,
        sdo_timeout=sdo_timeout,
        **more,
    )


def _by_node(value, what: str) -> dict:
    from cananalyze.core.errors import UsageError

    if value is None:
        return {}
    if isinstance(value, dict):
        items = list(value.items())
    else:
        items = []
        for entry in [value] if isinstance(value, (str, Path)) else value:
            node, sep, rest = str(entry).partition("=")
            if not sep:
                raise UsageError(f"{what}: give {{node: value}} or 'NODE=VALUE' (got {entry!r})")
            items.append((node, rest))
    out = {}
    for node, v in items:
        try:
            n = int(node, 0) if isinstance(node, str) else int(node)
        except (TypeError, ValueError):
            raise UsageError(f"{what}: node-IDs are 1..127 (got {node!r})") from None
        out[n] = v
    return out
