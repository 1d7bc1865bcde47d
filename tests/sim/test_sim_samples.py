"""The committed scenario samples: reproducible, and decoding to what samples/README.md lists."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from conftest import SAMPLES

from cananalyze.decode.sdo.processor import SdoProcessor
from cananalyze.decode.sdo.tracker import SdoTracker
from cananalyze.formats.source import read_all
from cananalyze.pipeline import Decoder, Options, build_decoder
from cananalyze.protocol.services import Service
from cananalyze.sim.samples import write_samples

SUFFIXES = (".log", ".asc", ".blf")


def test_samples_regenerate_identically(tmp_path):
    for path in write_samples(tmp_path):
        committed = SAMPLES / path.name
        assert committed.read_bytes() == path.read_bytes(), (
            f"{path.name} differs: rerun python -m cananalyze.sim.samples samples/"
        )
        assert committed.stat().st_size < 1_000_000


def _decode(path):
    batch = read_all(path)
    dec = Decoder([SdoProcessor(SdoTracker(timeout=1.0))])
    out = dec.decode(batch)
    fin = dec.finish()
    sdo = [r for _, r in [*out.records, *fin.records] if r["kind"] == "sdo"]
    return batch, out, sdo


def _frames(batch, cob):
    rows = np.flatnonzero(batch.can_id == cob)
    return batch.t[rows], [batch.payload(int(i)) for i in rows]


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_commissioning_sample(suffix):
    batch, out, sdo = _decode(SAMPLES / f"commissioning{suffix}")
    services = out.service
    counts = {s: int((services == s).sum()) for s in Service}
    assert len(batch) == 1200  # the counts samples/README.md gives
    assert counts[Service.SYNC] == 114 and counts[Service.HEARTBEAT] == 345
    assert counts[Service.TPDO] == 376 and counts[Service.RPDO] == 20
    assert counts[Service.EMCY] == counts[Service.ERROR_FRAME] == 0
    assert len(sdo) == 46
    assert (services == Service.BOOTUP).sum() == 4
    assert sorted(out.node[services == Service.BOOTUP].tolist()) == [3, 5, 6, 7]
    _, nmt = _frames(batch, 0x000)
    assert nmt == [b"\x01\x00"]  # one NMT start-all
    # identity reads: every SDO transaction succeeds, all three protocols appear
    assert {r["result"] for r in sdo} == {"ok"}
    assert {r["protocol"] for r in sdo} == {"expedited", "segmented", "block"}
    by = {(r["node"], r["direction"], r["index"], r["subindex"]): r for r in sdo}
    assert by[(3, "upload", 0x1018, 1)]["data"] == "58000000"  # ANDIG vendor 0x58
    assert by[(5, "upload", 0x1018, 1)]["data"] == "cd030000"  # Datexel 0x3CD
    assert bytes.fromhex(by[(5, "upload", 0x1008, 0)]["data"]) == b"DAT 7014"
    assert bytes.fromhex(by[(7, "upload", 0x1008, 0)]["data"]) == b"CPS_DCON"
    block = [r for r in sdo if r["protocol"] == "block"]
    assert len(block) == 1 and bytes.fromhex(block[0]["data"]) == b"DAT 7130"
    # the DAT 7014 TPDO2 remap: disable, clear, map ch1 and ch3, every 5th SYNC, enable
    remap = [
        (r["index"], r["subindex"], r["data"])
        for r in sdo
        if r["node"] == 5 and r["direction"] == "download"
    ]
    assert remap[1:] == [
        (0x1801, 1, "85020080"),
        (0x1A01, 0, "00"),
        (0x1A01, 1, "10010164"),
        (0x1A01, 2, "10030164"),
        (0x1A01, 0, "02"),
        (0x1801, 2, "05"),
        (0x1801, 1, "85020000"),
    ]
    t_sync, _ = _frames(batch, 0x080)
    assert np.allclose(np.diff(t_sync), 0.1, atol=0.002)
    t_pdo, pdo = _frames(batch, 0x285)
    assert {len(p) for p in pdo} == {4}  # two INTEGER16 channels after the remap
    assert np.allclose(np.diff(t_pdo), 0.5, atol=0.005)  # every 5th SYNC
    temps = np.array([struct.unpack("<2h", p) for p in pdo]) / 10
    assert ((temps > 15) & (temps < 30)).all()  # RTD temperatures in degC, drifting
    t_hb, hb = _frames(batch, 0x703)
    assert set(hb[-5:]) == {b"\x05"} and np.allclose(np.diff(t_hb[5:]), 0.1, atol=0.001)
    assert (services == Service.GUARD_REQUEST).sum() > 50  # I-7231D supervised by guarding
    assert (services == Service.RPDO).sum() >= 16  # DAT 7130 and I-7231D outputs
    t_di, _ = _frames(batch, 0x183)  # MCB-560 digital inputs: inhibit 100 ms respected
    assert np.diff(t_di).min() >= 0.1 - 1e-5
    t_ai, _ = _frames(batch, 0x283)  # analog: inhibit 100 ms, event timer 200 ms
    assert np.diff(t_ai).min() >= 0.1 - 1e-5 and np.diff(t_ai).max() < 0.2 + 1e-3


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_faults_sample(suffix):
    batch, out, sdo = _decode(SAMPLES / f"faults{suffix}")
    t0 = batch.t[0] - 0.1 if suffix == ".asc" else 1767225600.0  # ASC times are relative
    rows = np.flatnonzero(out.service == Service.EMCY)
    emcy = [(int(out.node[i]), batch.payload(int(i))) for i in rows]
    mcb = [
        (struct.unpack_from("<H", d)[0], struct.unpack_from("<I", d, 4)[0])
        for n, d in emcy
        if n == 3
    ]
    assert mcb == [(0x8100, 0x40000000), (0x8130, 0x10000000), (0x8140, 0xC0000000), (0x0000, 0)]
    gw = [d for n, d in emcy if n == 7]
    assert gw == [bytes.fromhex("00FF810B02000000")]  # RS-485 module 0x02 timed out
    assert (out.service == Service.ERROR_FRAME).sum() == 3
    assert len(batch) == 933 and len(rows) == 5
    t_hb, _ = _frames(batch, 0x706)  # DAT 7130 heartbeat dropout (first frame: boot-up)
    gaps = np.diff(t_hb[1:])
    assert gaps.max() > 1.4 and np.sort(gaps)[-2] < 0.11
    t_di, _ = _frames(batch, 0x183)  # MCB-560 TPDO1 inhibit 100 ms broken once
    assert (np.diff(t_di) < 0.1 - 1e-5).sum() == 1
    t_ai, _ = _frames(batch, 0x283)  # MCB-560 TPDO2 event timer 200 ms stalls
    late = t_ai[1:][np.diff(t_ai) > 0.25] - t0
    assert len(late) == 1 and 8.5 < late[0] < 8.7
    t_ch, ch = _frames(batch, 0x285)  # DAT 7014 channel 3 out of range (0x7FFF)
    ch3 = np.array([struct.unpack("<2h", p)[1] for p in ch])
    assert (ch3 == 0x7FFF).any() and (ch3 < 500).sum() > 5
    failed = {
        (r["node"], r["index"], r["subindex"], r["abort_code"]) for r in sdo if r["result"] != "ok"
    }
    assert failed == {
        (5, 0x1018, 1, 0x06010002),
        (3, 0x2FFF, 0, 0x06020000),
        (5, 0x1008, 0, 0x05040000),
    }


def test_faults_signals_with_the_network_model():
    """Decoded as `decode --network samples/network.toml` does: the model follows the
    DAT 7014 remap, so TPDO2 carries ch1 and ch3 in degC, and ch3 leaves the Pt100 range."""
    dec = build_decoder(Options(network=SAMPLES / "network.toml"))
    out = dec.decode(read_all(SAMPLES / "faults.log"))
    blocks = [b for b in out.signals if b.node == 5 and b.pdo == "tpdo2"]
    assert blocks and all(set(b.columns) == {"ch1", "ch3"} for b in blocks)
    ch3 = np.concatenate([b.columns["ch3"] for b in blocks]).astype(float)
    assert blocks[0].units["ch3"] == "°C"
    assert np.isclose(ch3.max(), 3276.7)  # 0x7FFF: beyond the Pt100 range (-200..850 degC)
    normal = ch3[ch3 < 850]
    assert normal.size > 5 and ((normal > 15) & (normal < 25)).all()
    mcb = [b for b in out.signals if b.node == 3 and b.pdo == "tpdo2"]
    assert mcb and mcb[0].units.get("analog0") == "mV"
