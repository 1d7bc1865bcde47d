"""The built-in devices: every `decoders/<key>.eds` with its `<key>.toml` sidecar, found in
the folder (a new device is those two files and nothing else), plus the CiA 401/402
profiles' defaults, which need no EDS."""

from __future__ import annotations

import re
from functools import cache

from cananalyze.core.errors import InputError
from cananalyze.devices import catalog
from cananalyze.devices.catalog import PROFILE_KEYS, device_keys
from cananalyze.devices.family import KEYS
from cananalyze.devices.generic import generic_profile
from cananalyze.devices.profile import DeviceProfile, build_profile
from cananalyze.devices.sidecar import load_sidecar


@cache
def load_builtin(key: str) -> DeviceProfile:
    """A built-in profile by key (`builtin_keys()`, or cia402 / cia401)."""
    if key in PROFILE_KEYS:
        return generic_profile(KEYS[key])
    if key not in catalog.builtin_keys():
        raise InputError(f"unknown device profile {key!r} (known: {', '.join(device_keys())})")
    base = catalog.decoders_dir()
    sidecar = load_sidecar(base / f"{key}.toml")
    return build_profile(base / f"{key}.eds", sidecar, None)


def builtin_profiles() -> list[DeviceProfile]:
    return [load_builtin(k) for k in catalog.builtin_keys()]


def identify(
    vendor_id: int | None = None,
    product_code: int | None = None,
    device_type: int | None = None,
    device_name: str | None = None,
) -> DeviceProfile | None:
    """The built-in profile matching SDO-read 0x1018/0x1000/0x1008, or None.

    A given value that contradicts a profile excludes it; among the rest the most
    matched facts win, and a tie (e.g. only the Datexel vendor ID) gives None.
    """
    scored: list[tuple[int, DeviceProfile]] = []
    for prof in builtin_profiles():
        hints = prof.sidecar.identity if prof.sidecar else {}
        names = {_norm(n) for n in hints.get("device_names", [])} | {_norm(prof.device_name)}
        score = 0
        ok = True
        for given, known, weight in (
            (vendor_id, prof.vendor_id, 2),
            (product_code, prof.product_code, 2),
            (device_type, prof.device_type, 1),
        ):
            if given is None or known is None:
                continue
            if given != known:
                ok = False
            score += weight
        if device_name is not None:
            if _norm(device_name) in names:
                score += 3
            elif names - {""}:
                ok = False
        if ok and score >= 2:  # the device type alone is shared by many CiA 401 devices
            scored.append((score, prof))
    if not scored:
        return None
    scored.sort(key=lambda sp: -sp[0])
    if len(scored) > 1 and scored[0][0] == scored[1][0]:
        return None
    return scored[0][1]


def _norm(name: str | None) -> str:
    return re.sub(r"[\s_\-]+", "", name or "").upper()
