"""Which built-in devices there are: the keys of `decoders/<key>.eds` + `<key>.toml`, found in
the folder, and the CiA profiles' keys. No profile is loaded here, so the CLI's help can
list them without the cost of reading an EDS."""

from __future__ import annotations

from functools import cache
from pathlib import Path

PROFILE_KEYS = (
    "cia402",
    "cia401",
)  # CiA 4xx defaults without an EDS (devices/cia402.py, cia401.py)


def decoders_dir() -> Path:
    """Where the built-in profiles are: inside the wheel, else the checkout's decoders/."""
    pkg = Path(__file__).resolve().parents[1]  # the installed cananalyze/
    wheel = pkg / "_decoders"
    return wheel if wheel.is_dir() else pkg.parent / "decoders"


@cache
def builtin_keys() -> tuple[str, ...]:
    """The keys of the devices in decoders/: each `<key>.eds` that has a `<key>.toml`, sorted."""
    base = decoders_dir()  # looked up at call time: a test may point it elsewhere
    return tuple(sorted(p.stem for p in base.glob("*.eds") if p.with_suffix(".toml").is_file()))


def device_keys() -> tuple[str, ...]:
    """What `--device` and the network file's `device` take: the built-ins, then the profiles."""
    return builtin_keys() + PROFILE_KEYS
