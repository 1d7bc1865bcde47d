"""core/storage: paths and fsspec URLs told apart, opened and statted in one place."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from cananalyze.core import storage
from cananalyze.core.errors import UsageError

pytest.importorskip("fsspec")


def test_urls_and_paths():
    assert storage.is_url("s3://bucket/logs") and storage.is_url("file:///tmp/x")
    assert not storage.is_url("/data/s3:/bucket") and not storage.is_url("-")
    assert not storage.is_url(Path("s3://bucket"))  # a Path has lost its '//' already
    assert storage.protocol("S3://b/k") == "s3" and storage.protocol("/x") == "file"


def test_storage_options_are_a_json_object():
    assert storage.parse_options('{"anon": true}') == {"anon": True}
    assert storage.parse_options(None) == {}
    with pytest.raises(UsageError, match="not JSON"):
        storage.parse_options("{anon")
    with pytest.raises(UsageError, match="a JSON object is needed"):
        storage.parse_options("[1]")


def test_a_url_and_its_path_read_the_same_bytes_and_stat(tmp_path):
    f = tmp_path / "a.log"
    f.write_bytes(b"(1.0) can0 123#01\n")
    with storage.open_binary(str(f)) as a, storage.open_binary(f"file://{f}") as b:
        assert a.read() == b.read()
    local, remote = storage.stat_of(str(f)), storage.stat_of(f"file://{f}")
    assert local.regular and remote.regular and local.size == remote.size == f.stat().st_size
    assert local.mtime_ns == f.stat().st_mtime_ns
    with pytest.raises(FileNotFoundError):
        storage.open_binary(f"file://{tmp_path}/none.log")


def test_special_files_are_told(tmp_path):
    fifo = tmp_path / "p"
    os.mkfifo(fifo)
    st = storage.stat_of(str(fifo))
    assert not st.regular and st.kind == "FIFO"
    assert storage.stat_of(str(tmp_path)).kind == "directory"


def test_an_unknown_protocol_is_one_line():
    with pytest.raises(UsageError, match=r"^nope://b/k: unknown protocol 'nope'"):
        storage.filesystem("nope://b/k")
