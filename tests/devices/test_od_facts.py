"""The device files' facts (devices/od_facts.py): what a profile answers from its cache is
what canopen's parse of the same file answers, object by object, on every device file
we have (the built-ins, the XDD/XDC fixtures, the real EDS/DCF/XDD files); a warm cache
decodes without importing canopen, to the same bytes; a damaged entry is parsed again."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REAL, ROOT, SAMPLES

from cananalyze.core.errors import InputError
from cananalyze.devices import od_facts
from cananalyze.devices.eds import effective_value, object_info, read_od, variable
from cananalyze.devices.generic import _dictionary, generic_profile
from cananalyze.devices.profile import build_profile

SUFFIXES = {".eds", ".dcf", ".xdd", ".xdc", ".xpd"}
FILES = sorted(
    [*(ROOT / "decoders").glob("*.eds"), *(ROOT / "tests" / "data" / "xdd").iterdir()]
    + ([p for p in REAL.rglob("*") if p.suffix.lower() in SUFFIXES] if REAL.exists() else [])
)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("CANANALYZE_CACHE", str(folder))
    return folder


def _probes(od) -> list[tuple[int, int]]:
    """Every (index, sub-index) the file defines, a sub-index past each object's last,
    sub-index 0 and 1 of every object, and indices nobody defines."""
    out = {(0x1234, 0), (0x5FFF, 1), (0x1018, 9)}
    for index, entry in od.items():
        if type(index) is not int:
            continue
        subs = [s for s in getattr(entry, "subindices", {0: None}) if type(s) is int]
        out |= {(index, s) for s in subs} | {
            (index, 0),
            (index, 1),
            (index, max(subs, default=0) + 1),
        }
    return sorted(out)


def _answer(var, node_id):
    if var is None:
        return None
    return (
        var.name,
        int(var.data_type or 0),
        bool(var.pdo_mappable),
        effective_value(var, node_id),
    )


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
@pytest.mark.parametrize("node_id", [None, 5])
def test_cached_facts_answer_as_canopen(path, node_id, cache):
    try:
        od = read_od(path, node_id)
    except InputError:
        pytest.skip("a file canopen does not read (its error is tested elsewhere)")
    cold = build_profile(path, None, node_id)
    assert cold.parsed is not None and len(list(cache.iterdir())) == 1
    warm = build_profile(path, None, node_id)
    assert warm.facts.objects == cold.facts.objects and len(list(cache.iterdir())) == 1
    if path.parent.name == "decoders":  # a built-in device: from the cache, nothing parsed
        assert warm.parsed is None
    for p in (cold, warm):
        assert (p.vendor_id, p.product_code, p.device_type, p.device_name, p.node_id) == (
            cold.vendor_id,
            cold.product_code,
            cold.device_type,
            cold.device_name,
            getattr(od, "node_id", None) or node_id,
        )
    for index, sub in _probes(od):
        want = variable(od, index, sub)
        assert warm.object(index, sub) == object_info(od, index, sub, warm.node_id), (index, sub)
        for n in (None, 7):
            got = warm.value(index, sub, n)
            expect = effective_value(want, n if n is not None else warm.node_id) if want else None
            assert got == expect or (got != got and expect != expect), (index, sub, n)
        facts = warm.facts.variable(index, sub)
        if facts is not od_facts.UNSURE:
            assert _answer(facts, 3) == _answer(want, 3), (index, sub)
    assert [c.__dict__ for c in warm.pdos(5)] == [c.__dict__ for c in cold.pdos(5)]


def test_generic_profiles_facts_are_their_dictionary():
    """The CiA 401/402 profiles' facts and canopen dictionary come from one table."""
    for family in (401, 402):
        prof = generic_profile(family)
        od = _dictionary(family)
        assert prof.facts.objects == od_facts.OdFacts.from_od(od).objects
        for index, sub in _probes(od):
            assert prof.object(index, sub) == object_info(od, index, sub, None), (index, sub)


def test_a_warm_cache_decodes_without_canopen_to_the_same_bytes(cache):
    """The first run parses and caches; the second imports no canopen (nor python-can)
    and prints the same decode."""
    env = {**os.environ, "CANANALYZE_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    code = (
        "import sys, runpy; sys.argv = ['cananalyze', 'decode', sys.argv[1], '--network', "
        "sys.argv[2]]\n"
        "try:\n    runpy.run_module('cananalyze', run_name='__main__')\n"
        "except SystemExit:\n    pass\n"
        "print('canopen' in sys.modules, 'can' in sys.modules, file=sys.stderr)"
    )
    args = [sys.executable, "-c", code, str(SAMPLES / "faults.log"), str(SAMPLES / "network.toml")]
    runs = [subprocess.run(args, env=env, capture_output=True, text=True) for _ in range(2)]
    assert runs[0].stderr.splitlines()[-1] == "True True"
    assert runs[1].stderr.splitlines()[-1] == "False False"
    assert runs[0].stdout == runs[1].stdout and "node 5" in runs[0].stdout
    assert len(list(cache.glob("od-*.json"))) == 4  # the network file's four devices


def test_damaged_entries_are_parsed_again(cache):
    path = ROOT / "decoders" / "dat7014.eds"
    first = build_profile(path, None, None)
    (entry,) = cache.glob("od-*.json")
    text = entry.read_text()
    for damage in (text[: len(text) // 2], "[" * 100_000, '{"format": 99}', "", "\x00\xff"):
        entry.write_text(damage, encoding="utf-8", errors="surrogateescape")
        again = build_profile(path, None, None)
        assert again.parsed is not None  # parsed, not read from the damage
        assert again.pdos(5) == first.pdos(5) and again.facts.objects == first.facts.objects
        assert entry.read_text() == text  # and the entry written anew


def test_a_file_that_does_not_parse_is_not_cached(cache, tmp_path):
    bad = tmp_path / "bad.eds"
    bad.write_text("[1000]\nParameterName=Device type\nDataType=nonsense\n")
    for _ in range(2):
        with pytest.raises(InputError, match="bad.eds"):
            build_profile(bad, None, None)
    assert not cache.exists() or not list(cache.iterdir())


def test_an_edited_file_is_a_new_entry(cache, tmp_path):
    eds = tmp_path / "dev.eds"
    text = (ROOT / "decoders" / "dat7014.eds").read_text()
    eds.write_text(text)
    before = build_profile(eds, None, None)
    eds.write_text(text.replace("ProductName=", "ProductName=Edited "))
    after = build_profile(eds, None, None)
    assert after.parsed is not None and len(list(cache.glob("od-*.json"))) == 2
    assert after.name == "Edited " + before.name


def test_off_writes_nothing(monkeypatch, tmp_path):
    monkeypatch.setenv("CANANALYZE_CACHE", "off")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.setenv("HOME", str(tmp_path))
    build_profile(ROOT / "decoders" / "dat7014.eds", None, None)
    assert list(Path(tmp_path).rglob("*")) == []


def test_an_unwritable_cache_folder_costs_only_the_parse(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("CANANALYZE_CACHE", str(blocked / "cache"))
    prof = build_profile(ROOT / "decoders" / "dat7014.eds", None, None)
    assert prof.parsed is not None and prof.pdos(5)
