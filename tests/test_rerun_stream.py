"""The streaming .rrd writer (`export --rrd`) records what `write_rrd` records from a
whole Capture: every entity's values and times, series names, the header, the bus
load and the layout (blueprint), whatever the batch size; a failed export leaves
no file."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SAMPLES, generated_log, real_file
from test_table_stream import DEVICES, _batches

from cananalyze.capture import Collector
from cananalyze.errors import ProblemLog
from cananalyze.outputs.busload import load_series
from cananalyze.outputs.rerun import stream as rerun_stream
from cananalyze.outputs.rerun.send import write_rrd
from cananalyze.outputs.rerun.stream import StreamRrd, _LoadWindows

NETWORK = str(SAMPLES / "network.toml")
_SKIP = {"rerun.controls.RowId", "RecordingInfo:start_time"}


def _stream(log: Path, out: Path, size: int | None = None, bitrate=None, **kw) -> dict:
    with StreamRrd(out, str(log), kw.get("network") or "", bitrate) as s:
        for batch in _batches(log, size, **kw):
            s.add(batch)
        return s.close()


def _reference(log: Path, out: Path, size: int | None = None, bitrate=None, **kw) -> dict:
    collector = Collector(str(log))
    for batch in _batches(log, size, **kw):
        collector.add(batch)
    cap = collector.capture(ProblemLog(), kw.get("network") or "")
    return write_rrd(cap, out, bitrate)


def _rows(chunks) -> dict[tuple[str, bool], list]:
    """Rows per (entity, static), without row ids and the recording's start time."""
    out: dict[tuple[str, bool], list] = {}
    for chunk in chunks:
        rows = [
            tuple(sorted((k, repr(v)) for k, v in r.items() if k not in _SKIP))
            for r in chunk.to_record_batch().to_pylist()
        ]
        out.setdefault((chunk.entity_path, chunk.is_static), []).extend(r for r in rows if r)
    return out


def _layout(chunks) -> list:
    """The blueprint's views and containers: names, origins, kinds and settings, without
    the random ids that tie them together or the time they were sent."""
    out = []
    for chunk in chunks:
        for r in chunk.to_record_batch().to_pylist():
            kept = tuple(
                sorted(
                    (k, repr(v))
                    for k, v in r.items()
                    if k not in ("rerun.controls.RowId", "log_time", "blueprint")
                    and not k.endswith((":contents", ":root_container"))
                )
            )
            if kept:
                out.append(kept)
    return sorted(out)


def read(path: Path):
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    (blueprint,) = [s for s in reader.blueprints() if s.kind == "blueprint"]
    return _rows(reader.stream()), _layout(reader.stream(store=blueprint))


def assert_same_rrd(ref: Path, new: Path) -> None:
    (data_a, bp_a), (data_b, bp_b) = read(ref), read(new)
    assert set(data_a) == set(data_b)
    for key in data_a:
        # events of an SDO transfer that ends a batch later are sent with that batch
        assert sorted(data_a[key]) == sorted(data_b[key]), key
    assert bp_a == bp_b and any("node" in repr(row) for row in bp_b)


def _both(tmp_path: Path, log: Path, size: int | None = None, **kw) -> dict:
    ref = _reference(log, tmp_path / "ref.rrd", size, **kw)
    new = _stream(log, tmp_path / "new.rrd", size, **kw)
    assert new == ref
    assert_same_rrd(tmp_path / "ref.rrd", tmp_path / "new.rrd")
    return new


@pytest.mark.parametrize("name", ["demo.log", "faults.log", "commissioning.log", "faults.blf"])
def test_samples_same_rrd(tmp_path, name):
    counts = _both(tmp_path, SAMPLES / name, network=NETWORK, bitrate=250000)
    assert counts["/events"] > 0 and counts["/bus/load"] > 0


@pytest.mark.parametrize("size", [1, 7, 1000])
def test_batch_size_invariance(tmp_path, size):
    counts = _both(tmp_path, SAMPLES / "faults.log", size=size, network=NETWORK)
    assert any(p.endswith("/nmt") for p in counts)


def test_generated_devices_small_batches(tmp_path):
    counts = _both(tmp_path, generated_log(tmp_path, 30000), size=997, device=DEVICES)
    assert sum(1 for p in counts if "/tpdo2/" in p) >= 16


@pytest.mark.parametrize(
    "rel",
    ["hilch__canopen-message-interpreter/pcan2.trc", "collin80__SavvyCAN/candump.log"],
)
def test_real_logs_same_rrd(tmp_path, rel):
    _both(tmp_path, real_file(rel), size=512)


def test_bus_load_summed_in_batches_equals_whole_log():
    """Windows summed batch by batch, times going back before the first frame included,
    give `load_series`'s values, the short-tail rule too."""
    rng = np.random.default_rng(5)
    t = 50.0 + np.cumsum(rng.exponential(0.004, 5000))
    t[1000:1010] -= 40.3  # a channel whose clock lags: windows before the first frame
    bits = rng.integers(47, 135, t.size)
    windows = _LoadWindows(0.1)
    for a in range(0, t.size, 333):
        windows.add(t[a : a + 333], bits[a : a + 333])
    for bitrate in (None, 500000):
        starts, load = windows.series(bitrate)
        ref_starts, ref_load = load_series(t, bits, 0.1, bitrate)
        assert starts.tolist() == ref_starts.tolist() and load.tolist() == ref_load.tolist()


def test_failed_export_leaves_no_file(tmp_path, monkeypatch):
    def boom(*_a, **_k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(rerun_stream, "send_parts", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        _stream(SAMPLES / "faults.log", tmp_path / "x.rrd", size=50, network=NETWORK)
    assert list(tmp_path.iterdir()) == []


def test_cli_export_rrd_streams(tmp_path):
    log = SAMPLES / "faults.log"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cananalyze",
            "export",
            str(log),
            "--no-check",
            "--rrd",
            str(tmp_path / "e.rrd"),
        ]
        + ["--network", NETWORK, "--bitrate", "125000"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr
    # (rerun leaves an empty header value out in a fresh process only: give a network)
    _reference(log, tmp_path / "ref.rrd", network=NETWORK, bitrate=125000)
    assert_same_rrd(tmp_path / "ref.rrd", tmp_path / "e.rrd")
