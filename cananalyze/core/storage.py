"""Local paths and fsspec URLs (s3://, file://, any installed protocol): the one place that
tells them apart, finds their file system and opens them, for the readers and the fleet.

A URL is `PROTOCOL://...`; anything else is a local path, read with the standard library
as before. Credentials and endpoints come from `storage_options` (fleet and query:
`--storage-options JSON`) and from what fsspec and its back end read themselves: for
s3fs, AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY, AWS_ENDPOINT_URL, and fsspec's
FSSPEC_S3_ENDPOINT_URL. fsspec and s3fs are optional (the `s3` extra): a missing one,
or a protocol fsspec does not know, is one line, not a traceback.
"""

from __future__ import annotations

import json
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from cananalyze.core.errors import UsageError
from cananalyze.core.extras import need

_URL = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]*)://")
# protocols served by packages of their own: the extra that installs each
_BACKENDS = {"s3": ("s3fs", "s3"), "s3a": ("s3fs", "s3")}


def is_url(name: str | Path) -> bool:
    """True for `PROTOCOL://...` (a Path never is: `Path("s3://b")` is `s3:/b`)."""
    return isinstance(name, str) and _URL.match(name) is not None


def protocol(url: str) -> str:
    match = _URL.match(url)
    return match.group(1).lower() if match else "file"


def parse_options(text: str | None) -> dict:
    """`--storage-options` (a JSON object) as a dict; UsageError for anything else."""
    if not text:
        return {}
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise UsageError(f"--storage-options: not JSON ({exc})") from None
    if not isinstance(value, dict):
        raise UsageError("--storage-options: a JSON object is needed, e.g. '{\"anon\": true}'")
    return value


def filesystem(url: str, options: dict | None = None) -> tuple[Any, str]:
    """(fsspec file system, path within it) of a URL; MissingExtra or one-line UsageError."""
    fsspec = need("fsspec", "object storage", "s3")
    proto = protocol(url)
    module, extra = _BACKENDS.get(proto, (None, None))
    if module is not None:
        need(module, f"{proto}:// URLs", extra)
    try:
        from fsspec.core import url_to_fs

        return url_to_fs(url, **(options or {}))
    except ValueError as exc:
        if proto not in fsspec.available_protocols():
            raise UsageError(
                f"{url}: unknown protocol {proto!r} (no fsspec file system has it)"
            ) from None
        raise UsageError(f"{url}: {' '.join(str(exc).split())}") from None
    except ImportError as exc:  # a back end fsspec knows but is not installed
        raise UsageError(f"{url}: {' '.join(str(exc).split())}") from None
    except TypeError as exc:  # an option the back end does not take
        raise UsageError(f"--storage-options: {exc}") from None


def url_of(fs, path: str) -> str:
    """`path` as a listing of `fs` gives it (no protocol) back into a URL."""
    return path if is_url(path) else fs.unstrip_protocol(path)


def open_binary(name: str | Path, options: dict | None = None) -> BinaryIO:
    """A path or URL opened for reading bytes (OSError as `open` raises them)."""
    if not is_url(name):
        return open(name, "rb")  # noqa: SIM115 - the caller closes it
    fs, path = filesystem(str(name), options)
    try:
        return fs.open(path, "rb")
    except FileNotFoundError:
        raise FileNotFoundError(2, "No such file or directory", str(name)) from None
    except IsADirectoryError:
        raise IsADirectoryError(21, "Is a directory", str(name)) from None


@dataclass(frozen=True)
class Stat:
    """What a rerun's skip key needs of a file, and whether it is one."""

    size: int | None
    mtime_ns: int | None
    regular: bool
    kind: str = "file"  # else: "directory", "FIFO", "character device", ...


_KINDS = (
    (stat.S_ISDIR, "directory"),
    (stat.S_ISFIFO, "FIFO"),
    (stat.S_ISCHR, "character device"),
    (stat.S_ISBLK, "block device"),
    (stat.S_ISSOCK, "socket"),
)


def stat_of(name: str | Path, options: dict | None = None, info=None) -> Stat:
    """Size, modification time (ns) and kind of a path or URL (`info`: fsspec's, when
    a listing already gave it; for a path, its `os.stat` when a folder's walk made it).
    OSError when it is not there."""
    if not is_url(name):
        st = info if isinstance(info, os.stat_result) else os.stat(name)
        if stat.S_ISREG(st.st_mode):
            return Stat(st.st_size, st.st_mtime_ns, True)
        kind = next((k for test, k in _KINDS if test(st.st_mode)), "special file")
        return Stat(None, None, False, kind)
    if info is None:
        fs, path = filesystem(str(name), options)
        info = fs.info(path)
    if info.get("type") == "directory":
        return Stat(None, None, False, "directory")
    return Stat(int(info.get("size") or 0), listed_mtime_ns(info), True)


def listed_mtime_ns(info: dict) -> int | None:
    """fsspec back ends name the modification time differently (s3: LastModified)."""
    for key in ("LastModified", "mtime", "last_modified", "updated", "created"):
        value = info.get(key)
        if value is None:
            continue
        if hasattr(value, "timestamp"):
            return int(value.timestamp() * 1_000_000_000)
        try:
            return int(float(value) * 1_000_000_000)
        except (TypeError, ValueError):
            continue
    return None  # unknown: such a file is hashed on every run
