"""SRDO (CiA 304) end to end: configured by SDO writes that python-canopen's SDO client makes
(over python-can's virtual bus, the frames re-timed here: no wall-clock timing), the pairs
encoded as CANopenNode does, decoded and judged by the `srdo` rule.

The reference encoding is CANopenNode's 304/CO_SRDO.c (commit 9b8beed8): the mapping's odd
sub-indices fill the normal frame and the even ones the inverted frame (line 541,
`plain_inverted = i % 2`), and a consumer requires every byte of the inverted frame to be
the bit inversion of the normal frame's (lines 887-894); the inverted frame is due within
SRVT of the normal one (line 875) and the next pair within SCT (lines 880 and 970).
SRDO 1 of node 5 uses the default COB-IDs 0x0FF + 2 * 5 = 0x109 and 0x10A (CO_SRDO.c
lines 467-473, 301/CO_driver.h line 401).
"""

from __future__ import annotations

import binascii
import json
import os
import subprocess
import sys
from pathlib import Path

import canopen
import pytest
from canopen.objectdictionary import UNSIGNED8, UNSIGNED16, UNSIGNED32, ODRecord

import cananalyze
from tests.helpers.virtual_bus import sdo_download_frames, variable

ROOT = Path(__file__).resolve().parents[2]
NODE = 5
NORMAL, INVERTED = 0x109, 0x10A
SCT_MS, SRVT_MS = 20, 10

# SRDO1 of node 5 produced (direction 1), SCT 20 ms, SRVT 10 ms, default COB-IDs, one
# UNSIGNED16 and its inverted copy mapped (0x2000:01 normal, 0x2001:01 inverted)
CONFIG = [
    (0x1301, 1, 1, 1),
    (0x1301, 2, SCT_MS, 2),
    (0x1301, 3, SRVT_MS, 1),
    (0x1301, 5, NORMAL, 4),
    (0x1301, 6, INVERTED, 4),
    (0x1381, 0, 0, 1),
    (0x1381, 1, 0x20000110, 4),
    (0x1381, 2, 0x20010110, 4),
    (0x1381, 0, 2, 1),
    (0x13FE, 0, 0xA5, 1),  # configuration valid (CO_SRDO_VALID_MAGIC)
]


def _od() -> canopen.ObjectDictionary:
    od = canopen.ObjectDictionary()
    comm = ODRecord("SRDO1 communication parameter", 0x1301)
    comm.add_member(variable(0x1301, 0, "Highest sub-index", UNSIGNED8, "ro", 6))
    comm.add_member(variable(0x1301, 1, "Information direction", UNSIGNED8, "rw", 0))
    comm.add_member(variable(0x1301, 2, "Refresh time", UNSIGNED16, "rw", 0))
    comm.add_member(variable(0x1301, 3, "Validation time", UNSIGNED8, "rw", 0))
    comm.add_member(variable(0x1301, 4, "Transmission type", UNSIGNED8, "rw", 254))
    comm.add_member(variable(0x1301, 5, "COB-ID normal", UNSIGNED32, "rw", 0xFF))
    comm.add_member(variable(0x1301, 6, "COB-ID inverted", UNSIGNED32, "rw", 0x100))
    od.add_object(comm)
    mapping = ODRecord("SRDO1 mapping parameter", 0x1381)
    mapping.add_member(variable(0x1381, 0, "Number of entries", UNSIGNED8, "rw", 0))
    for sub in (1, 2):
        mapping.add_member(variable(0x1381, sub, f"Entry {sub}", UNSIGNED32, "rw", 0))
    od.add_object(mapping)
    od.add_object(variable(0x13FE, 0, "Configuration valid", UNSIGNED8, "rw", 0))
    crc = ODRecord("Safety configuration checksum", 0x13FF)
    crc.add_member(variable(0x13FF, 0, "Highest sub-index", UNSIGNED8, "ro", 1))
    crc.add_member(variable(0x13FF, 1, "SRDO1", UNSIGNED16, "rw", 0))
    od.add_object(crc)
    return od


def _sdo_writes(writes: list[tuple[int, int, int, int]]) -> list[list[tuple[int, bytes]]]:
    """python-canopen's SDO client writes each (index, sub, value, size) to node 5."""
    return sdo_download_frames(NODE, _od(), writes)


@pytest.fixture(scope="module")
def config_frames() -> list[tuple[int, bytes]]:
    return [f for write in _sdo_writes(CONFIG) for f in write]


def srdo_pair(value: int) -> tuple[bytes, bytes]:
    """An UNSIGNED16 as CANopenNode sends it: normal, then the inverted copy."""
    normal = value.to_bytes(2, "little")
    return normal, bytes(b ^ 0xFF for b in normal)


def _log(tmp_path: Path, rows: list[tuple[float, int, bytes]]) -> Path:
    path = tmp_path / "srdo.log"
    lines = [f"({t:.6f}) can0 {cid:03X}#{data.hex().upper()}" for t, cid, data in sorted(rows)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _stream(config_frames, pairs: int = 10, start: float = 1.0, period: float = 0.020):
    """The configuration at 0.1 s (1 ms a frame), NMT start of node 5, then `pairs` SRDO
    pairs every `period` s, each inverted frame 0.5 ms after its normal one."""
    rows = [(0.1 + 0.001 * k, cid, data) for k, (cid, data) in enumerate(config_frames)]
    rows.append((0.5, 0x000, bytes([0x01, NODE])))
    for k in range(pairs):
        normal, inverted = srdo_pair(0x1234 + k)
        t = start + k * period
        rows += [(t, NORMAL, normal), (t + 0.0005, INVERTED, inverted)]
    return rows


def _findings(log: Path, rule: str = "srdo"):
    f = cananalyze.load(log).findings
    return f[f.rule == rule].reset_index(drop=True)


def test_healthy_stream_is_decoded_once_per_pair_and_has_no_finding(tmp_path, config_frames):
    cap = cananalyze.load(_log(tmp_path, _stream(config_frames)))
    assert cap.findings.empty, cap.findings.to_dict("records")  # no srdo, no unknown_cob_id
    s = cap.signals
    assert set(s.pdo) == {"srdo1"} and set(s.cob_id) == {NORMAL}  # the normal frame only
    assert list(s.signal.unique()) == ["obj_2000_01"]
    assert list(s.value) == [0x1234 + k for k in range(10)]
    assert set(s.node) == {NODE}
    frames = cap.frames
    services = frames.set_index("can_id").service.astype(str)
    assert set(services.loc[NORMAL]) == {"srdo"} and set(services.loc[INVERTED]) == {
        "srdo_inverted"
    }


def test_corrupted_inverted_frame_is_one_finding(tmp_path, config_frames):
    rows = _stream(config_frames)
    k = next(i for i, r in enumerate(rows) if r[1] == INVERTED and r[0] > 1.05)
    t, cid, data = rows[k]
    rows[k] = (t, cid, bytes([data[0] ^ 0x01, data[1]]))  # one bit not inverted
    f = _findings(_log(tmp_path, rows))
    assert len(f) == 1, f.to_dict("records")
    assert f.severity[0] == "error" and f.node[0] == NODE and f.cob_id[0] == INVERTED
    assert "is not the bit inversion of the normal frame" in f.message[0]
    assert f.t[0] == pytest.approx(t)


def test_late_inverted_frame_is_one_finding(tmp_path, config_frames):
    rows = _stream(config_frames)
    k = next(i for i, r in enumerate(rows) if r[1] == INVERTED and r[0] > 1.05)
    t, cid, data = rows[k]
    rows[k] = (t - 0.0005 + 0.015, cid, data)  # 15 ms after its normal frame, SRVT 10 ms
    f = _findings(_log(tmp_path, rows))
    assert len(f) == 1, f.to_dict("records")
    assert "validation time SRVT 10 ms" in f.message[0]
    assert f.measured[0] == 15.0 and f.expected[0] == SRVT_MS
    assert f["basis"][0].startswith("0x1301:3 written at")


def test_missed_refresh_is_one_finding(tmp_path, config_frames):
    rows = [r for r in _stream(config_frames) if not 1.099 < r[0] < 1.101]  # pair 5 lost
    assert len(rows) == len(_stream(config_frames)) - 2
    f = _findings(_log(tmp_path, rows))
    assert len(f) == 1, f.to_dict("records")
    assert "refresh time SCT 20 ms" in f.message[0]
    assert f.measured[0] == 40.0 and f.t[0] == pytest.approx(1.08)


def test_missing_inverted_frame_is_one_finding(tmp_path, config_frames):
    rows = [r for r in _stream(config_frames) if r[:2] != (1.1005, INVERTED)]
    f = _findings(_log(tmp_path, rows))
    assert len(f) == 1, f.to_dict("records")
    assert "without its inverted frame" in f.message[0] and f.t[0] == pytest.approx(1.1)


def test_gfc_is_reported_as_information(tmp_path, config_frames):
    rows = _stream(config_frames) + [(1.5, 0x001, b"")]
    f = _findings(_log(tmp_path, rows))
    assert len(f) == 1 and f.severity[0] == "info"
    assert f.message[0] == "global fail-safe command (GFC)" and f.cob_id[0] == 1


def test_refresh_judged_by_the_sct_in_force(tmp_path, config_frames):
    """Pairs every 40 ms: too slow for SCT 20 ms, on time once 0x1301:2 says 50 ms."""
    (raise_sct,) = _sdo_writes([(0x1301, 2, 50, 2)])
    rows = _stream(config_frames, pairs=4, period=0.040)  # 1.00-1.12 under SCT 20 ms
    rows += [(1.13, cid, data) for cid, data in raise_sct[:1]]
    rows += [(1.131, cid, data) for cid, data in raise_sct[1:]]
    for k in range(4, 10):  # 1.16-1.36 under SCT 50 ms
        normal, inverted = srdo_pair(k)
        rows += [(1.0 + 0.04 * k, NORMAL, normal), (1.0005 + 0.04 * k, INVERTED, inverted)]
    f = _findings(_log(tmp_path, rows))
    assert list(f.t.round(3)) == [1.0, 1.04, 1.08], f.to_dict("records")  # before the write
    assert set(f.expected) == {SCT_MS}


def test_no_refresh_finding_while_the_producer_is_stopped(tmp_path, config_frames):
    rows = [r for r in _stream(config_frames) if not 1.079 < r[0] < 1.141]  # 4 pairs gap
    rows += [(1.065, 0x000, bytes([0x02, NODE])), (1.13, 0x000, bytes([0x01, NODE]))]
    assert _findings(_log(tmp_path, rows)).empty


def test_a_log_starting_between_the_two_frames_says_nothing(tmp_path, config_frames):
    rows = _stream(config_frames)
    rows.append((0.9995, INVERTED, srdo_pair(0)[1]))  # the pair's normal frame is not logged
    assert _findings(_log(tmp_path, rows)).empty


def test_srdo_known_by_its_pattern_on_the_default_cob_ids(tmp_path, config_frames):
    """Nothing configures the SRDO: a pair on node 5's default COB-IDs, the second frame
    the bit inversion of the first, makes both (and 0x001, the GFC) known; the inversion
    is judged from then on, the times (not known) are not."""
    rows = [r for r in _stream(config_frames) if r[1] in (NORMAL, INVERTED)]
    rows.append((1.5, 0x001, b""))
    k = next(i for i, r in enumerate(rows) if r[1] == INVERTED and r[0] > 1.05)
    t, cid, data = rows[k]
    rows[k] = (t, cid, bytes([data[0], data[1] ^ 0x80]))
    del rows[-5:-3]  # a pair lost: the SCT is not known, nothing said
    cap = cananalyze.load(_log(tmp_path, rows))
    f = cap.findings
    assert list(f.rule) == ["srdo", "srdo"], f.to_dict("records")
    assert "is not the bit inversion" in f.message[0] and f.t[0] == pytest.approx(t)
    assert f.severity[1] == "info" and "GFC" in f.message[1]
    services = cap.frames.set_index("can_id").service.astype(str)
    assert set(services.loc[NORMAL]) == {"srdo"} and set(services.loc[INVERTED]) == {
        "srdo_inverted"
    }
    assert cap.signals.empty  # the mapping is not known


def test_srdo_identifiers_without_the_pattern_stay_unknown(tmp_path):
    rows = [(1.0 + 0.02 * k, NORMAL + (k % 2), bytes([k, 2 * k])) for k in range(6)]
    f = _findings(_log(tmp_path, rows), "unknown_cob_id")
    assert set(f.cob_id) == {NORMAL, INVERTED}


def test_text_and_jsonl_name_the_pair(tmp_path, config_frames):
    log = _log(tmp_path, _stream(config_frames, pairs=2) + [(1.5, 0x001, b"")])
    run = [sys.executable, "-m", "cananalyze", "decode", str(log)]
    text = subprocess.run(run, capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert "srdo             5  SRDO1 normal  obj_2000_01=4660" in text
    assert "srdo_inverted    5  SRDO1 inverted" in text
    assert "GFC global fail-safe command" in text
    assert "SRDO1 communication: Refresh time SCT (ms)" in text  # the SDO write named
    out = subprocess.run(
        [*run, "--format", "jsonl"], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout
    frames = [r for r in map(json.loads, out.splitlines()) if r.get("kind") == "frame"]
    normal = [r for r in frames if r["can_id"] == NORMAL]
    assert [r["signals"] for r in normal] == [{"obj_2000_01": 0x1234}, {"obj_2000_01": 0x1235}]
    assert {r["service"] for r in normal} == {"srdo"} and {r["pdo"] for r in normal} == {1}
    inverted = [r for r in frames if r["can_id"] == INVERTED]
    assert {r["service"] for r in inverted} == {"srdo_inverted"}
    assert all("signals" not in r for r in inverted)
    assert [r["service"] for r in frames if r["can_id"] == 1] == ["gfc"]


def _signature() -> int:
    """CONFIG's CRC as CO_SRDO_config computes it (CO_SRDO.c lines 512-527: direction, SCT,
    SRVT, both COB-IDs, the count, then each entry's sub-index and value, little-endian),
    with the standard library's CRC-CCITT (binascii.crc_hqx), not cananalyze's."""
    data = bytes([1]) + SCT_MS.to_bytes(2, "little") + bytes([SRVT_MS])
    data += NORMAL.to_bytes(4, "little") + INVERTED.to_bytes(4, "little") + bytes([2])
    data += bytes([1]) + (0x20000110).to_bytes(4, "little")
    data += bytes([2]) + (0x20010110).to_bytes(4, "little")
    return binascii.crc_hqx(data, 0)


@pytest.mark.parametrize("wrong", [False, True])
def test_configuration_signature_is_checked_when_made_valid(tmp_path, wrong):
    crc = _signature() ^ (0x0100 if wrong else 0)
    writes = _sdo_writes([*CONFIG[:-1], (0x13FF, 1, crc, 2), CONFIG[-1]])
    rows = _stream([f for w in writes for f in w], pairs=3)
    f = _findings(_log(tmp_path, rows))
    if not wrong:
        assert f.empty, f.to_dict("records")
        return
    assert len(f) == 1, f.to_dict("records")
    assert f.message[0] == (
        f"SRDO1 configuration signature 0x13FF:1 is 0x{crc:04X}, its parameters give "
        f"0x{_signature():04X}: the node will not run it"
    )
    assert f["basis"][0].startswith("0x13FF:1 written at")


NETWORK = """
[nodes.5.srdo.1]                 # the default COB-IDs of node 5's SRDO 1: 0x109, 0x10A
direction = "tx"
sct_ms = 20
srvt_ms = 10
mapping = ["2000:01/16", "2001:01/16"]
"""


def test_srdo_declared_in_the_network_file(tmp_path, config_frames):
    """No SDO in the log: the network file's SRDO decodes and is judged from the start."""
    (tmp_path / "net.toml").write_text(NETWORK)
    rows = [r for r in _stream(config_frames) if r[1] in (NORMAL, INVERTED, 0x000)]
    rows = [r for r in rows if not 1.099 < r[0] < 1.101]  # pair 5 lost
    cap = cananalyze.load(_log(tmp_path, rows), network=tmp_path / "net.toml")
    f = cap.findings
    assert list(f.rule) == ["srdo"], f.to_dict("records")
    assert "refresh time SCT 20 ms" in f.message[0]
    assert f["basis"][0] == "0x1301:2 in the network file"
    assert list(cap.signals.value) == [0x1234 + k for k in range(10) if k != 5]


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("[nodes.5.srdo.1]\ncob_id = 0x10A\n", "an SRDO's normal COB-ID is odd, 0x101-0x17F"),
        ("[nodes.5.srdo.2]\nsct_ms = 20\n", "srdo 2 needs a cob_id"),
        ('[nodes.5.srdo.1]\nmapping = ["2000:01/16"]\n', "an even number of entries"),
        ('[nodes.5.srdo.1]\ndirection = "up"\n', "expected tx or rx"),
    ],
)
def test_network_file_srdo_errors_name_the_key(tmp_path, text, error):
    (tmp_path / "net.toml").write_text(text)
    log = _log(tmp_path, [(1.0, NORMAL, b"\x00")])
    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(log), "--network", "net.toml"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 2 and error in done.stderr and "net.toml:" in done.stderr


def test_live_tick_reports_an_overdue_pair_once(tmp_path):
    """Live: the decoder's tick at the bus's clock (no wall clock here) reports a pair
    overdue by SCT once; the pair that ends the silence is not reported again."""
    from cananalyze.core.frames import from_rows
    from cananalyze.pipeline import Options, build_decoder

    (tmp_path / "net.toml").write_text(NETWORK)
    decoder = build_decoder(Options(network=str(tmp_path / "net.toml"), checks=True))
    rows = []
    for k in range(3):
        normal, inverted = srdo_pair(k)
        rows += [(1.0 + 0.02 * k, NORMAL, normal), (1.0005 + 0.02 * k, INVERTED, inverted)]
    decoder.decode(from_rows(rows))
    assert decoder.tick(1.05) is None  # 10 ms after the last pair: on time
    late = decoder.tick(1.07)  # 30 ms: past SCT 20 ms + the 2 ms jitter floor
    found = [f for f in late.findings.findings() if f.rule == "srdo"]
    assert len(found) == 1 and "no pair since" in found[0].message
    assert decoder.tick(1.2) is None
    normal, inverted = srdo_pair(9)
    out = decoder.decode(from_rows([(1.3, NORMAL, normal), (1.3005, INVERTED, inverted)]))
    assert not [f for f in out.findings.findings() if f.rule == "srdo"]


def test_declared_identifiers_are_not_taken_for_an_srdo(tmp_path, config_frames):
    """known_cob_ids in the network file: the pair pattern there is that traffic, not SRDO."""
    (tmp_path / "net.toml").write_text(f"known_cob_ids = [{NORMAL}, {INVERTED}]\n")
    rows = [r for r in _stream(config_frames) if r[1] in (NORMAL, INVERTED)]
    cap = cananalyze.load(_log(tmp_path, rows), network=tmp_path / "net.toml")
    assert cap.findings.empty and cap.signals.empty
    assert set(cap.frames.service.astype(str)) == {"other"}


def test_srdo_from_the_eds(tmp_path):
    """The SRDO in node 5's EDS (written by python-canopen's export_od), its COB-IDs the
    stored defaults 0x0FF/0x100 that CANopenNode adds 2 x node-ID to (CO_SRDO.c lines
    467-473): 0x109/0x10A on node 5. No SDO in the log."""
    from canopen.objectdictionary import export_od

    od = _od()
    od[0x1301][1].default, od[0x1301][2].default, od[0x1301][3].default = 1, SCT_MS, SRVT_MS
    od[0x1381][0].default = 2
    od[0x1381][1].default, od[0x1381][2].default = 0x20000110, 0x20010110
    eds = tmp_path / "srdo.eds"
    export_od(od, str(eds), doc_type="eds")
    rows = [r for r in _stream([]) if r[1] in (NORMAL, INVERTED)]
    rows = [r for r in rows if not 1.099 < r[0] < 1.101]  # pair 5 lost
    cap = cananalyze.load(_log(tmp_path, rows), eds={NODE: str(eds)})
    assert list(cap.signals.value) == [0x1234 + k for k in range(10) if k != 5]
    f = cap.findings
    assert list(f.rule) == ["srdo"] and "refresh time SCT 20 ms" in f.message[0]
    assert f["basis"][0] == "0x1301:2 profile default"


def test_a_log_ending_inside_the_windows_says_nothing(tmp_path, config_frames):
    """The last pair's SCT window, and the last normal frame's SRVT window, run past the
    end of the log: what comes after is not in it, so neither is a finding (the API and
    `check --json`, read back with json)."""
    rows = _stream(config_frames)
    rows.append((rows[-1][0] + 0.019, NORMAL, srdo_pair(0x99)[0]))  # inverted not logged
    rows.append((rows[-1][0] + 0.004, 0x705, bytes([0x05])))  # the log ends 4 ms later
    log = _log(tmp_path, rows)
    assert _findings(log).empty
    out = tmp_path / "findings.json"
    run = [sys.executable, "-m", "cananalyze", "check", str(log), "--json", str(out)]
    done = subprocess.run(run, capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert json.loads(out.read_text()) == []
    # the same log with the last pair's inverted frame corrupted: that pair is judged
    k = max(i for i, r in enumerate(rows) if r[1] == INVERTED)
    rows[k] = (rows[k][0], INVERTED, b"\x00\x00")
    f = _findings(_log(tmp_path, rows))
    assert len(f) == 1 and "is not the bit inversion" in f.message[0]
