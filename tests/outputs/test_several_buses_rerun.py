"""The Rerun recording of a log of several buses (export and live) keeps each bus's own
entities: drive 1 on can0 and drive 1 on can1 (test_several_buses_drives.py) each get
their signals, NMT and drive lanes, and each bus its own load (two buses' loads summed
read over 100 %). Read back with rerun's own reader, load() and python-can.

Every test here fails when the recording merges the buses."""

from __future__ import annotations

import collections
from pathlib import Path

import can
import numpy as np
import pytest
from exported import decoded_batches, read_rrd

from cananalyze import load
from cananalyze.cli.main import main
from cananalyze.protocol.busload import frame_bits, load_series
from tests.decode.test_several_buses_drives import DEVICE, _log

BITRATE = 250_000


def _expected(cap) -> dict[str, list]:
    """Entity -> the (time ns, value) rows load() says it should hold, per bus."""
    out: dict[str, list] = collections.defaultdict(list)
    ns = lambda t: int(np.float64(t) * 1e9)  # noqa: E731
    for s in cap.series:
        for col, values in s.columns.items():
            out[f"/{s.bus}/node/{s.node}/{s.pdo}/{col}"] += [
                (ns(t), float(v)) for t, v in zip(s.t, values, strict=True)
            ]
    nmt = cap.events[cap.events.kind == "nmt_state"]
    for t, bus, node, msg in zip(nmt.t, nmt.bus, nmt.node, nmt.message, strict=True):
        out[f"/{bus}/node/{node}/nmt"].append((ns(t), msg.split("NMT state ")[1]))
    ds = cap.drive_states
    for t, bus, node, state in zip(ds.t, ds.bus, ds.node, ds.state, strict=True):
        out[f"/{bus}/node/{node}/drive_state"].append((ns(t), state))
    return {k: sorted(v) for k, v in out.items()}


def _load_per_bus(log: Path) -> dict[str, np.ndarray]:
    """Each channel's bus load in percent of BITRATE from the frames python-can reads."""
    frames = collections.defaultdict(list)
    with can.LogReader(str(log)) as reader:
        for m in reader:
            frames[m.channel].append((m.timestamp, m.dlc, m.is_extended_id))
    out = {}
    for ch, rows in frames.items():
        t, dlc, ext = (np.array(c) for c in zip(*rows, strict=True))
        flags = np.where(ext, 1, 0).astype(np.uint8)
        out[ch] = load_series(t, frame_bits(flags, dlc.astype(np.uint8)), 0.1, BITRATE)[1]
    return out


def _check_recording(rrd, cap, log: Path) -> None:
    expected = _expected(cap)
    assert {"/can0/node/1/drive_state", "/can1/node/1/nmt"} <= set(expected)
    for entity, want in expected.items():
        got = [(t, v) for t, v in rrd.values(entity, _COMPONENT[entity.rsplit("/", 1)[1]])]
        assert got == want, entity
    assert not [e for e in rrd.rows if e.startswith(("/node/", "/bus/"))]  # nothing merged
    for ch, want in _load_per_bus(log).items():
        got = [v for _, v in rrd.values(f"/{ch}/bus/load", "Scalars:scalars")]
        assert got == pytest.approx(want.tolist())
        assert rrd.static[f"/{ch}/bus/load"]["SeriesLines:names"] == [f"{ch} bus load [%]"]
    text = [r["TextLog:text"][0] for r in rrd.rows["/events"]]
    assert any(t.startswith("can1 node 1: drive state fault") for t in text)
    views = repr(rrd.layout)
    for name in ("can0 node 1 TPDO1 (0x181)", "can1 node 1 TPDO1 (0x181)"):
        assert name in views
    for lane in ("/can0/node/1/nmt", "/can1/node/1/drive_state", "/can1/bus/load"):
        assert f"+ {lane}" in views


_COMPONENT = collections.defaultdict(
    lambda: "Scalars:scalars", nmt="StateChange:state", drive_state="StateChange:state"
)


def test_rerun_export_per_bus(tmp_path):
    log = _log(tmp_path)
    out = tmp_path / "x.rrd"
    args = ["export", str(log), "--device", "1=cia402", "--rrd", str(out)]
    main([*args, "--bitrate", str(BITRATE), "-q"])
    _check_recording(read_rrd(out), load(str(log), device=DEVICE), log)


@pytest.mark.parametrize("size", [7, None])
def test_rerun_live_per_bus(tmp_path, size):
    """The live session's recorder, fed the decoded batches as they come, sends each
    bus's entities and bus load on its own (its windows aligned to the clock)."""
    from cananalyze.outputs.rerun.live import RerunLive

    log = _log(tmp_path)
    out = tmp_path / "live.rrd"
    live = RerunLive(rrd=out, bitrate=BITRATE, every=0.0)
    for batch in decoded_batches(log, size, device=DEVICE):
        live.add(batch)
    live.close()
    rrd = read_rrd(out, layout=False)
    expected = _expected(load(str(log), device=DEVICE))
    for entity, want in expected.items():
        got = rrd.values(entity, _COMPONENT[entity.rsplit("/", 1)[1]])
        assert got == want, entity
    loads = {e for e in rrd.rows if e.endswith("/bus/load")}
    assert loads == {"/can0/bus/load", "/can1/bus/load"}
    per_bus = _load_per_bus(log)
    for ch in ("can0", "can1"):  # the same bits, in clock-aligned windows
        got = [v for _, v in rrd.values(f"/{ch}/bus/load", "Scalars:scalars")]
        assert max(got) < 100
        assert sum(got) == pytest.approx(float(per_bus[ch].sum()), rel=0.05)
