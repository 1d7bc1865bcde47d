"""The fleet's inputs: files, folders (recursive) and globs, into a sorted list of log files,
each with the options for its folder (a `network.toml` beside the logs)."""

from __future__ import annotations

import glob
from dataclasses import replace
from pathlib import Path

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


def _in_folder(folder: Path, skip: Path | None) -> list[Path]:
    out = []
    for p in folder.rglob("*"):
        if not p.is_file() or any(part.startswith(".") for part in p.relative_to(folder).parts):
            continue
        if skip is not None and p.resolve().is_relative_to(skip):
            continue  # the dataset inside an input folder
        if p.suffix.lower() not in NOT_LOGS:
            out.append(p)
    return out


def expand(inputs: list[str], dataset: str | Path | None = None) -> list[Path]:
    """Every log file the inputs name, once each, sorted; UsageError for one that is not there."""
    skip = Path(dataset).resolve() if dataset is not None else None
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
                files = _in_folder(m, skip)
            elif m.is_file() or m.exists():
                files = [m]
            else:
                raise UsageError(f"{m}: no such file or folder")
            for f in files:
                found.setdefault(f.resolve(), f.absolute())
    return sorted(found.values())


def options_for(log: Path, opts: Options) -> Options:
    """The options for one log: its folder's network.toml, when there is one, takes the
    place of --network (the folder's file describes that installation)."""
    folder_file = log.parent / FOLDER_NETWORK
    if folder_file.is_file():
        return replace(opts, network=folder_file)
    return opts
