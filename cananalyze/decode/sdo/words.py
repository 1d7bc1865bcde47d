"""The `words` field of an SDO record: its value in words (protocol.object_words), with
the node's own names for the objects a PDO mapping entry points at."""

from __future__ import annotations

from cananalyze.devices.object_words import object_words


def sdo_words(node, index, sub, value, data: bytes | None, name, object_info) -> str | None:
    """Words for one completed transfer (None: nothing to add to its value)."""
    if not isinstance(node, int):
        return None

    def name_of(i: int, s: int) -> str | None:
        known = object_info(node, i, s) if object_info is not None else None
        return known[0] if known else None

    return object_words(index, sub, value, data, name, name_of)
