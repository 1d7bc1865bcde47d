"""The fuzz targets of tests/fuzz/targets.py, a short derandomized run in CI (issue 24):
configuration, EDS and XDD/XDC loaders give InputError or a result, never another exception;
junk between good candump frames never costs a good frame; an export of damaged input
leaves no hidden file. `CANANALYZE_FUZZ=N` multiplies the budget with fresh inputs."""

from __future__ import annotations

import random
import time
import tracemalloc

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.fuzz import targets
from tests.fuzz.strategies import fuzz_settings, mutated

CONFIGS = {
    "network.yaml": targets.GOOD_NETWORK,
    "network.toml": targets.GOOD_TOML,
    "rules.yaml": targets.GOOD_RULES,
}


def _bounded(fn, *args, seconds: float = 5.0, mb: int = 200):
    """Run a target; its time and its peak of Python allocations must stay bounded."""
    tracemalloc.start()
    t0 = time.process_time()
    try:
        return fn(*args)
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert time.process_time() - t0 < seconds
        assert peak < mb << 20, f"{peak >> 20} MB"


def test_good_inputs_load():
    for kind, data in CONFIGS.items():
        targets.load_config(data, kind)  # no error at all
    targets.load_eds(targets.GOOD_EDS)


@fuzz_settings(60)
@given(st.sampled_from(sorted(CONFIGS)), st.data())
def test_mutated_configuration_files(kind, data):
    blob = data.draw(mutated(CONFIGS[kind], max_ops=6))
    _bounded(targets.load_config, blob, kind)


@fuzz_settings(40)
@given(mutated(targets.GOOD_EDS, max_ops=6), st.sampled_from([".eds", ".dcf"]))
def test_mutated_eds(blob, suffix):
    _bounded(targets.load_eds, blob, suffix)


def test_good_xdd_loads():
    assert targets.XDD_SEEDS
    for seed in targets.XDD_SEEDS:
        targets.load_xdd(seed.read_bytes(), seed.suffix)  # no error at all


@fuzz_settings(20)
@given(st.integers(0, 2**32 - 1), st.sampled_from([".xdd", ".xdc", ".eds"]))
def test_mutated_xdd(seed, suffix):
    """Well-formed XDDs whose attributes and elements are changed: the reader's meaning."""
    rng = random.Random(seed)
    blob = targets.mutate_xml(rng, rng.choice(targets.XDD_SEEDS).read_bytes())
    _bounded(targets.load_xdd, blob, suffix, seconds=10.0)


@pytest.mark.parametrize("k", range(len(targets.HOSTILE_XML)))
def test_hostile_xml_refused_in_bounds(k):
    _bounded(targets.load_xdd, targets.HOSTILE_XML[k], ".xdd")


@fuzz_settings(40)
@given(st.integers(0, 2**32 - 1), st.integers(1, 300))
def test_junk_between_frames_keeps_every_good_frame(seed, frames):
    blob, want = targets.junk_mixed(random.Random(seed), frames)
    assert _bounded(targets.kept_frames, blob) == want


@fuzz_settings(8)
@given(data=st.data())
def test_export_of_damaged_input_leaves_no_hidden_file(tmp_path_factory, data):
    from conftest import SAMPLES

    src = data.draw(st.sampled_from(["demo.log", "demo.asc", "demo.blf"]))
    blob = data.draw(mutated((SAMPLES / src).read_bytes(), max_ops=3))
    out = tmp_path_factory.mktemp("export")
    assert targets.export_leaves_nothing(blob, "." + src.split(".")[1], out) == []
