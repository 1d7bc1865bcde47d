"""The fleet's inputs: files, folders (recursive) and globs, local or at URLs (s3://...,
core/storage), into a sorted list of log files, each with the options for its folder (a
`network.toml` beside local logs)."""

from __future__ import annotations

import glob
import os
from dataclasses import replace
from pathlib import Path
from stat import S_ISREG

from cananalyze.core import storage
from cananalyze.core.errors import UsageError
from cananalyze.pipeline import Options

FOLDER_NETWORK = "network.toml"
# In a folder, files with these suffixes are descriptions, not logs (device files,
# configurations, notes, our own output); a file named on the command line is always read.
NOT_LOGS = {
    ".eds",
    ".dcf",
    ".xdd",
    ".xdc",
    ".xpd",
    ".dbc",
    ".sym",
    ".arxml",
    ".md",
    ".rst",
    ".yaml",
    ".yml",
    ".toml",
    ".json",
    ".ini",
    ".xml",
    ".py",
    ".pdf",
    ".png",
    ".jpg",
    ".parquet",
    ".rrd",
    ".zip",
}


def _in_folder(folder: Path, skip: Path | None, stats: dict) -> list[tuple[Path, Path]]:
    """(the path as found, the file itself) of each log under `folder`: regular files,
    recursively (symbolic links to folders not followed), hidden names, the descriptions
    (NOT_LOGS) and the dataset left out. One `scandir` a folder and one `stat` a file,
    kept in `stats` (the rerun's skip key needs nothing else of it); the file itself is
    its folder's real path and its name, resolved alone only when it is a link."""
    out = []
    start = folder.absolute()
    stack = [(str(start), os.path.realpath(start))]
    while stack:
        top, real = stack.pop()
        if skip is not None and Path(real).is_relative_to(skip):
            continue  # the dataset inside an input folder
        try:
            with os.scandir(top) as found:
                entries = list(found)
        except PermissionError:
            continue
        for e in entries:
            if e.name.startswith("."):
                continue
            if e.is_dir(follow_symlinks=False):
                stack.append((e.path, os.path.join(real, e.name)))
                continue
            if os.path.splitext(e.name)[1].lower() in NOT_LOGS:
                continue
            try:
                st = e.stat()
            except OSError:
                continue  # a broken link
            if not S_ISREG(st.st_mode):
                continue
            itself = os.path.realpath(e.path) if e.is_symlink() else os.path.join(real, e.name)
            if skip is not None and Path(itself).is_relative_to(skip):
                continue
            out.append((Path(e.path), Path(itself)))
            stats[e.path] = st
    return out


def _is_log(name: str) -> bool:
    parts = name.split("/")
    return not any(p.startswith(".") for p in parts) and Path(name).suffix.lower() not in NOT_LOGS


def _expand_url(
    item: str, dataset: str | Path | None, options: dict | None, infos: dict
) -> list[str]:
    """The log files one URL input names: an object, a prefix (recursive) or a glob;
    what the listing said of each goes into `infos` (size, time: no request per file)."""
    fs, path = storage.filesystem(item, options)
    skip = None
    if dataset is not None and storage.is_url(dataset):
        skip = storage.filesystem(str(dataset), options)[1].rstrip("/") + "/"
    try:
        if any(c in path for c in "*?["):
            matches = fs.glob(path, detail=True)
            if not matches:
                raise UsageError(f"{item}: no file matches")
        elif fs.isdir(path):
            base = path.rstrip("/") + "/"
            matches = {
                p: info
                for p, info in fs.find(path, detail=True).items()
                if _is_log(p[len(base) :]) and not (skip and p.startswith(skip))
            }
        elif fs.isfile(path):
            matches = {path: fs.info(path)}
        else:
            raise UsageError(f"{item}: no such file or folder")
    except OSError as exc:
        raise UsageError(f"{item}: cannot list: {' '.join(str(exc).split())}") from None
    out = []
    for p, info in matches.items():
        if info.get("type") != "directory":
            out.append(storage.url_of(fs, p))
            infos[out[-1]] = info
    return sorted(out)


def expand(
    inputs: list[str],
    dataset: str | Path | None = None,
    options: dict | None = None,
    infos: dict | None = None,
) -> list[str]:
    """Every log file the inputs name (absolute paths, URLs as given), once each, sorted;
    UsageError for one that is not there. `options`: fsspec's, for URL inputs; `infos`
    gets what their listing said of each URL, and the `os.stat` of each file found in a
    local folder (core/storage.stat_of takes both)."""
    urls: set[str] = set()
    local_inputs = []
    infos = {} if infos is None else infos
    for item in inputs:
        if storage.is_url(item):
            urls.update(_expand_url(item, dataset, options, infos))
        else:
            local_inputs.append(item)
    local = [str(p) for p in _expand_local(local_inputs, dataset, infos)]
    return local + sorted(urls)


def _expand_local(inputs: list[str], dataset: str | Path | None, stats: dict) -> list[Path]:
    skip = Path(dataset).resolve() if dataset is not None and not storage.is_url(dataset) else None
    # the file itself -> the path it was found by (a link's folder is the one that counts)
    found: dict[Path, Path] = {}
    for item in inputs:
        if any(c in item for c in "*?["):
            matches = [Path(m) for m in sorted(glob.glob(item, recursive=True))]
            if not matches:
                raise UsageError(f"{item}: no file matches")
        else:
            matches = [Path(item)]
        for m in matches:
            if m.is_dir():
                files = _in_folder(m, skip, stats)
            elif m.is_file() or m.exists():
                files = [(m.absolute(), m.resolve())]
            else:
                raise UsageError(f"{m}: no such file or folder")
            for f, itself in files:
                found.setdefault(itself, f)
    return sorted(found.values())


def options_for(log: str | Path, opts: Options) -> Options:
    """The options for one log: its folder's network.toml, when there is one, takes the
    place of --network (the folder's file describes that installation). Not read beside
    logs at URLs: give --network."""
    if storage.is_url(log):
        return opts
    folder_file = Path(log).parent / FOLDER_NETWORK
    if folder_file.is_file():
        return replace(opts, network=folder_file)
    return opts
