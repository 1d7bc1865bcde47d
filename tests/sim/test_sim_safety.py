"""`simulate --scenario safety` / `safety-faults`: SRDO and MPDO traffic configured by the
network file the decoder reads (the same keys), simulated to a log, read back with
python-can's reader (independent of our decoder) and decoded with `cananalyze.load()`.

The SRDO checks are CANopenNode's consumer conditions (304/CO_SRDO.c, commit 9b8beed8,
lines 866-983): every byte of the inverted frame is the bit inversion of the normal
frame's (lines 887-894), it follows within SRVT (line 875) and the next pair within SCT
(lines 880 and 970); SRDO 1 of node 5 is on 0x0FF + 2 * 5 = 0x109 / 0x10A (lines 467-473).
The MPDO frames are checked against the layout lely-core builds (src/co/tpdo.c lines
710-715 and 773-776: byte 0 the node-ID, | 0x80 for DAM; index LE; sub-index; value).
"""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import can
import pytest

import cananalyze

ROOT = Path(__file__).resolve().parents[2]
SCT_MS, SRVT_MS = 20, 10
NORMAL, INVERTED = 0x109, 0x10A
SAM_COB, DAM_COB = 0x387, 0x487
# node 7's scanner list: 0x6401:01..02 (block 2 << 24 | index << 8 | first sub-index)
SCANNER = (2 << 24) | (0x6401 << 8) | 0x01
# node 6's dispatching list: node 7's 0x6401:02 into its own 0x6200:01 (block 1 << 56 |
# consumer index << 40 | its sub-index << 32 | producer's index << 16 | sub << 8 | node-ID)
DISPATCH = (1 << 56) | (0x6200 << 40) | (1 << 32) | (0x6401 << 16) | (2 << 8) | 7
NETWORK = f"""
[nodes.5]
device = "dat7014"
gfc = true

[nodes.5.srdo.1]
sct_ms = {SCT_MS}
srvt_ms = {SRVT_MS}
mapping = ["2000:01/16", "2001:01/16"]

[nodes.6]
device = "dat7130"
object_dispatching_list = [0x{DISPATCH:016X}]

[nodes.7]
device = "i7231d"
object_scanner_list = [0x{SCANNER:08X}]

[nodes.7.tpdo.3]
cob_id = 0x{SAM_COB:03X}
mpdo = "sam"
transmission_type = 254
event_timer = 50

[nodes.7.tpdo.4]
cob_id = 0x{DAM_COB:03X}
mapping = ["6200:01/8"]
mpdo = "dam"
transmission_type = 254
event_timer = 100
"""


@pytest.fixture(scope="module")
def net(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("safety") / "net.toml"
    path.write_text(NETWORK)
    return path


def _simulate(net: Path, scenario: str, seed: int = 3) -> Path:
    out = net.parent / f"{scenario}-{seed}.log"
    if not out.exists():
        run = [sys.executable, "-m", "cananalyze", "simulate", "--network", str(net)]
        run += ["--scenario", scenario, "--to", str(out), "--seed", str(seed), "--duration", "5"]
        subprocess.run(run, check=True, capture_output=True, cwd=ROOT)
    return out


def _frames(log: Path) -> list[can.Message]:
    return list(can.LogReader(str(log)))


def test_srdo_pairs_meet_the_consumers_conditions(net):
    msgs = [m for m in _frames(_simulate(net, "safety")) if m.arbitration_id in (NORMAL, INVERTED)]
    normals = [m for m in msgs if m.arbitration_id == NORMAL]
    assert len(normals) > 200  # 5 s, a pair inside every 20 ms SCT
    for a, b in zip(msgs[::2], msgs[1::2], strict=True):
        assert (a.arbitration_id, b.arbitration_id) == (NORMAL, INVERTED)
        assert bytes(b.data) == bytes(x ^ 0xFF for x in a.data)
        assert 0 < b.timestamp - a.timestamp < SRVT_MS / 1000
    gaps = [b.timestamp - a.timestamp for a, b in zip(normals, normals[1:], strict=False)]
    assert max(gaps) < SCT_MS / 1000


def test_healthy_run_decodes_srdo_and_mpdo_without_srdo_findings(net):
    log = _simulate(net, "safety")
    cap = cananalyze.load(log, network=net)
    f = cap.findings
    assert f[f.rule == "srdo"].empty, f.to_dict("records")
    s = cap.signals
    srdo = s[s.pdo == "srdo1"]
    assert set(srdo.node) == {5} and set(srdo.cob_id) == {NORMAL}
    msgs = _frames(log)
    assert not [m for m in msgs if m.arbitration_id == 0x001]  # GFC valid, but no fault
    sent = [struct.unpack("<H", bytes(m.data))[0] for m in msgs if m.arbitration_id == NORMAL]
    assert list(srdo.value) == sent and sent[:3] == [0, 1, 2]  # the producer's pair counter
    # SAM: node 7's scanner list objects in turn, each value the frame's bytes 4-5
    sam = [bytes(m.data) for m in msgs if m.arbitration_id == SAM_COB]
    assert {(d[0], struct.unpack_from("<HB", d, 1)) for d in sam} == {
        (7, (0x6401, 1)),
        (7, (0x6401, 2)),
    }
    got = s[s.cob_id == SAM_COB].reset_index(drop=True)
    assert len(got) == len(sam)
    raw = [struct.unpack_from("<H", d, 4)[0] for d in sam]
    first = [d[3] == 1 for d in sam]
    # 0x6401:01 is the I-7231D's analog input, named and scaled (V) by its profile: one scale
    volts = got[first]
    assert set(volts.signal) == {"ai0_i7012"} and set(volts.unit) == {"V"}
    ratio = volts.value.to_numpy() / [r for r, f in zip(raw, first, strict=True) if f]
    assert ratio.min() == pytest.approx(ratio.max(), rel=1e-5)  # float32 values
    # 0x6401:02 (not in node 7's profile: the frame counter, as sent) goes to node 6's
    # 0x6200:01 by its dispatching list: named as that object (not node 7's 0x6401:02)
    other = [r for r, f in zip(raw, first, strict=True) if not f]
    second = got[[not f for f in first]]
    assert list(second.value.astype(int)) == other
    assert set(second.signal) == {"obj_6200_01"}
    run = [sys.executable, "-m", "cananalyze", "decode", str(log), "--network", str(net)]
    text = subprocess.run(run, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert "TPDO3 MPDO from node 7 0x6401:02 -> node 6 0x6200:01  obj_6200_01=" in text
    assert "TPDO4 MPDO to all nodes 0x6200:01" in text and "SRDO1 inverted" in text
    # DAM: to every node (0x80 | 0), the object of the mapping's entry 1
    dam = [bytes(m.data) for m in msgs if m.arbitration_id == DAM_COB]
    assert dam and {d[:4] for d in dam} == {bytes([0x80, 0x00, 0x62, 0x01])}
    assert len(s[s.cob_id == DAM_COB]) == len(dam)


def test_same_seed_same_log(net, tmp_path):
    a = _simulate(net, "safety")
    run = [sys.executable, "-m", "cananalyze", "simulate", "--network", str(net)]
    b = tmp_path / "again.log"
    run += ["--scenario", "safety", "--to", str(b), "--seed", "3", "--duration", "5"]
    subprocess.run(run, check=True, capture_output=True, cwd=ROOT)
    assert a.read_bytes() == b.read_bytes()


def test_fault_variant_gives_the_srdo_findings(net):
    """One pair not inverted, then (GFC valid on node 5: `gfc = true`, 0x1300 = 1) a GFC
    with no data, as CANopenNode's CO_GFCsend sends it; one inverted frame past SRVT."""
    log = _simulate(net, "safety-faults")
    f = cananalyze.load(log, network=net).findings
    f = f[f.rule == "srdo"].reset_index(drop=True)
    assert list(f.severity) == ["error", "info", "error"], f.to_dict("records")
    assert "not the bit inversion" in f.message[0]
    assert f.message[1] == "global fail-safe command (GFC)" and f.cob_id[1] == 0x001
    assert 0 < f.t[1] - f.t[0] < 0.001
    assert f"validation time SRVT {SRVT_MS} ms" in f.message[2]
    assert f.measured[2] > SRVT_MS
    gfc = [m for m in _frames(log) if m.arbitration_id == 0x001]
    assert len(gfc) == 1 and gfc[0].dlc == 0


def test_no_gfc_unless_valid(net, tmp_path):
    other = tmp_path / "net.toml"
    other.write_text(NETWORK.replace("gfc = true", "gfc = false"))
    log = _simulate(other, "safety-faults")
    f = cananalyze.load(log, network=other).findings
    assert list(f[f.rule == "srdo"].severity) == ["error", "error"]
