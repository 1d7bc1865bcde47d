"""`export --rrd` records the log `load()` decodes, read back with rerun's own reader
(`rerun.chunk.RrdReader`): every signal's values and times, series names, NMT lanes, the
event log, the header, the bus load and the layout (blueprint); the same recording
whatever the batch size; a failed export leaves no file."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SAMPLES, generated_log, real_file
from exported import (
    DEVICES,
    NETWORK,
    assert_rrd_is,
    assert_same_rrd,
    decoded_batches,
    export,
    load_cut,
)

import cananalyze
from cananalyze.outputs.rerun import stream as rerun_stream
from cananalyze.outputs.rerun.stream import StreamRrd, _LoadWindows
from cananalyze.protocol.busload import load_series


def _stream(log: Path, out: Path, size: int | None = None, bitrate=None, **kw) -> dict:
    """The .rrd writer fed directly (no run, no rules), batches of `size` frames."""
    with StreamRrd(out, str(log), kw.get("network") or "", bitrate) as s:
        for batch in decoded_batches(log, size, **kw):
            s.add(batch)
        return s.close()


def _as_load(tmp_path: Path, log: Path, size: int | None = None, bitrate=None, **kw):
    """Export the log as .rrd; it must hold load()'s log of the same options."""
    out = export(log, tmp_path, ("rrd",), size, bitrate, **kw)["rrd"]
    return assert_rrd_is(load_cut(log, size, bitrate=bitrate, **kw), out, bitrate)


@pytest.mark.parametrize("name", ["demo.log", "faults.log", "commissioning.log", "faults.blf"])
def test_samples_rrd_is_load(tmp_path, name):
    r = _as_load(tmp_path, SAMPLES / name, bitrate=250000, network=NETWORK)
    load = [v for _, v in r.values("/bus/load", "Scalars:scalars")]
    assert r.rows["/events"] and 0 < max(load) < 100  # percent of 250 kbit/s


@pytest.mark.parametrize("size", [1, 7, 1000])
@pytest.mark.slow
def test_batch_size_invariance(tmp_path, size):
    """Cut anywhere (a frame at a time, like live), the recording is that of one batch."""
    log = SAMPLES / "faults.log"
    whole = export(log, tmp_path / "whole", ("rrd",), network=NETWORK)["rrd"]
    r = _as_load(tmp_path / "cut", log, size, network=NETWORK)
    assert any(p.endswith("/nmt") for p in r.rows)
    assert_same_rrd(whole, tmp_path / "cut" / "x.rrd")


def test_generated_devices_small_batches(tmp_path):
    r = _as_load(tmp_path, generated_log(tmp_path, 30000), 997, device=DEVICES)
    assert sum(1 for p in r.rows if "/tpdo2/" in p) >= 16


@pytest.mark.parametrize(
    "rel",
    ["hilch__canopen-message-interpreter/pcan2.trc", "collin80__SavvyCAN/candump.log"],
)
def test_real_logs_rrd_is_load(tmp_path, rel):
    _as_load(tmp_path, real_file(rel), size=512)


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


def test_cli_export_rrd_is_load(tmp_path):
    """`export --rrd` (the rules on, by default) records load()'s log, findings included."""
    log = SAMPLES / "faults.log"
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", str(log), "--rrd", str(tmp_path / "e.rrd")]
        + ["--network", NETWORK, "--bitrate", "125000"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr
    cap = cananalyze.load(log, network=NETWORK, bitrate=125000)
    rec = assert_rrd_is(cap, tmp_path / "e.rrd", bitrate=125000)
    texts = [row["TextLog:text"][0] for row in rec.rows["/events"]]
    assert sum(t.startswith("[") for t in texts) == len(cap.findings) > 0
