"""JSON values as the lines hold them: NaN and infinities as null, numpy scalars as numbers,
bytes as hex; one `dumps` for every JSON line (rows and columns alike)."""

from __future__ import annotations

import json

import numpy as np


def clean(value):
    if isinstance(value, float) and (value != value or value in (float("inf"), float("-inf"))):
        return None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, bytes):
        return value.hex()
    return value


def clean_fields(fields: dict) -> dict:
    """A row's fields as the JSON line holds them (nested dicts cleaned one level down)."""
    return {
        k: {kk: clean(vv) for kk, vv in v.items()} if isinstance(v, dict) else clean(v)
        for k, v in fields.items()
    }


def dumps(rec: dict) -> str:
    return json.dumps(rec, separators=(",", ":"), ensure_ascii=False, default=clean)
