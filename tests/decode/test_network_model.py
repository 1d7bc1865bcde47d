"""Network model and PDO decoding: configuration written inside the log, manual demos, real logs."""

from __future__ import annotations

import cantools
import numpy as np
import pytest

from cananalyze.config.netfile import load_network
from cananalyze.config.spec import NetworkSpec, NodeSpec
from cananalyze.core.errors import InputError
from cananalyze.core.frames import from_rows
from cananalyze.decode.model import NetworkModel
from cananalyze.decode.pdo_processor import PdoDecoder
from cananalyze.decode.sdo.processor import SdoProcessor
from cananalyze.devices.builtin import load_builtin
from cananalyze.devices.profile import load_eds
from cananalyze.formats.source import read_all
from cananalyze.outputs.fields import row_fields
from cananalyze.pipeline import Decoder
from cananalyze.protocol.services import Service
from tests.conftest import real_file, seed_file


def run(fb, spec=None):
    model = NetworkModel(spec or NetworkSpec())
    decoder = Decoder([SdoProcessor(), model, PdoDecoder(model)])
    model.attach(decoder)
    return model, decoder.decode(fb)


def sdo_write(node, index, sub, value, size=4):
    cmd = {1: 0x2F, 2: 0x2B, 4: 0x23}[size]
    req = bytes([cmd, index & 0xFF, index >> 8, sub]) + value.to_bytes(4, "little")
    resp = bytes([0x60, index & 0xFF, index >> 8, sub, 0, 0, 0, 0])
    return [(0x600 + node, req), (0x580 + node, resp)]


def frames_at(seq, t0=0.0, dt=0.001):
    return from_rows([(t0 + i * dt, cob, data) for i, (cob, data) in enumerate(seq)])


def block(batch, cob):
    found = [b for b in batch.signals if b.cob_id == cob]
    assert found, f"no signals for 0x{cob:03X}"
    return found


def test_log2_mapping_written_by_sdo_inside_the_log():
    path = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    eds = real_file("SeonilChoi__CANOPEN-SDK/ZeroErr_Driver_V1.5.eds")
    model, batch = run(read_all(path), NetworkSpec({11: NodeSpec(load_eds(eds, 11), "user --eds")}))
    (tpdo,) = block(batch, 0x18B)
    assert tpdo.node == 11 and tpdo.pdo == "tpdo1" and tpdo.rows.size == 586
    assert list(tpdo.columns) == ["statusword", "position_actual_value"]
    # first TPDO: "40 02 01 00 00 00" -> statusword 0x0240, position 1; third "40 02 FF FF FF FF" -> -1
    assert tpdo.columns["statusword"][:3].tolist() == [0x240, 0x240, 0x240]
    assert tpdo.columns["position_actual_value"][:3].tolist() == [1, 0, -1]
    (rpdo,) = block(batch, 0x20B)
    assert list(rpdo.columns) == ["controlword", "target_position"]
    cfg = model.config_at(11)
    assert [(e.index, e.bits) for e in cfg.pdo_config(cfg.pdos[("tx", 1)]).mapping] == [
        (0x6041, 16),
        (0x6064, 32),
    ]
    assert model.known(11, 0x1006, 0, batch.frames.t[-1]) == (1000, "log")
    assert cfg.pdos[("rx", 1)].transmission_type == 255
    objects = [c.object for c in model.history]
    assert (0x1800, 1) in objects and (0x1A00, 2) in objects
    # no frame of TPDO1 is flagged: DLC 6 = 2 + 4 mapped bytes
    assert not any("pdo_problem" in n for _, n in batch.row_notes)


def test_log2_without_profile_still_follows_the_mapping():
    model, batch = run(read_all(real_file("SeonilChoi__CANOPEN-SDK/log2.txt")))
    (tpdo,) = block(batch, 0x18B)
    assert list(tpdo.columns) == ["obj_6041_00", "obj_6064_00"]
    assert tpdo.columns["obj_6064_00"][2] == 0xFFFFFFFF
    assert model.config_at(11).identified_by == "unknown"


def test_i7231d_dynamic_mapping_onto_0x182_and_0x202():
    # The manual's "5th TxPDO" is 0x1805/0x1A05, i.e. TPDO6 by CiA 301 numbering (0x1800 = TPDO1).
    seed_file("002_8af3d3370e33cdbc.txt")
    seq = [(0x182, bytes.fromhex("01"))]  # before the remap: TPDO1 of node 2
    seq += sdo_write(1, 0x1805, 1, 0x182)
    seq += sdo_write(1, 0x1A05, 1, 0x60000108) + sdo_write(1, 0x1A05, 2, 0x60000208)
    seq += sdo_write(1, 0x1A05, 3, 0x64010110) + sdo_write(1, 0x1A05, 0, 3, 1)
    seq += sdo_write(1, 0x1405, 1, 0x202)
    seq += sdo_write(1, 0x1605, 1, 0x62000108) + sdo_write(1, 0x1605, 2, 0x62000208)
    seq += sdo_write(1, 0x1605, 3, 0x64110110) + sdo_write(1, 0x1605, 0, 3, 1)
    seq += [(0x202, bytes.fromhex("AB900000")), (0x182, bytes.fromhex("546F0600"))]
    fb = frames_at(seq)
    model, batch = run(fb, NetworkSpec({1: NodeSpec(load_builtin("i7231d"), "user --device")}))
    assert (batch.node[0], batch.pdo[0], batch.service[0]) == (2, 1, Service.TPDO)
    last = len(fb) - 1
    assert (batch.node[last], batch.pdo[last], batch.service[last]) == (1, 6, Service.TPDO)
    assert (batch.node[last - 1], batch.pdo[last - 1], batch.service[last - 1]) == (
        1,
        6,
        Service.RPDO,
    )
    tx = [b for b in block(batch, 0x182) if b.node == 1][0]
    assert tx.pdo == "tpdo6" and tx.columns["di_byte1"].tolist() == [0x54]
    assert tx.columns["ai0_i7012"][0] == pytest.approx(0.002, abs=5e-4)  # "the AI0 value is 0.002V"
    (rx,) = block(batch, 0x202)
    assert rx.pdo == "rpdo6" and rx.rows.tolist() == [last - 1]
    assert [v[0] for v in rx.columns.values()][:2] == [0xAB, 0x90]  # "0x90AB for the DO0-DO15"
    assert model.config_at(1).pdos[("tx", 6)].cob_id == 0x182


def test_dat7014_sensor_type_written_mid_log_changes_units_from_next_frame():
    prof = load_builtin("dat7014")
    cob = next(p.cob_id for p in prof.pdos(5) if p.direction == "tx" and p.valid and p.mapping)
    pdo = bytes.fromhex("E8030000") + bytes(4)  # ch1 = 1000
    seq = [(cob, pdo)] + sdo_write(5, 0x2107, 1, 0x10, 1) + [(cob, pdo)]
    _, batch = run(frames_at(seq), NetworkSpec({5: NodeSpec(prof, "user --device")}))
    first, second = block(batch, cob)
    assert first.rows.tolist() == [0] and second.rows.tolist() == [3]
    assert first.units["ch1"] == "°C" and first.columns["ch1"][0] == pytest.approx(100.0)
    assert second.units["ch1"] == "Ω" and second.columns["ch1"][0] == pytest.approx(1000.0)
    assert row_fields(batch, 3)["units"]["ch1"] == "Ω"


def test_axiomatic_network_file_matches_cantools(tmp_path):
    eds = real_file("calumroy__CANopen_socketCAN_Test/EDS-23123-1.01.eds")
    log = real_file("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log")
    dbc = cantools.database.load_file(
        str(real_file("calumroy__CANopen_socketCAN_Test/axiomatic_23123-1.dbc"))
    )
    net = tmp_path / "net.toml"
    lines = [f'[nodes.127]\neds = "{eds}"']
    for n, subs in ((1, range(1, 5)), (2, range(5, 9)), (3, range(9, 13))):
        words = ", ".join(f'"7100:{s:02X}/16"' for s in subs)
        lines.append(
            f"[nodes.127.tpdo.{n}]\ncob_id = 0x{0xFF + 0x100 * n:03X}\ntransmission_type = 254\n"
            f"event_timer = 100\nmapping = [{words}]"
        )
    net.write_text("\n".join(lines) + "\n")
    fb = read_all(log)
    model, batch = run(fb, load_network(net))
    for cob in (0x1FF, 0x2FF, 0x3FF):
        (b,) = block(batch, cob)
        msg = dbc.get_message_by_frame_id(cob)
        for k in (0, 1, b.rows.size - 1):
            row = int(b.rows[k])
            want = list(msg.decode(fb.payload(row), decode_choices=False, scaling=False).values())
            assert [col[k] for col in b.columns.values()] == want
    assert model.config_at(127).identified_by == "network file"
    assert model.config_at(127).pdos[("tx", 1)].event_timer == 100


def test_tmcm1636_dcf_and_log_writes():
    dcf = real_file("nigel-bruce-khan__ros_canopen-tmcm-1636/TMCM-1636-CANopen.dcf")
    fb = read_all(real_file("nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt"))
    model, batch = run(fb, NetworkSpec({1: NodeSpec(load_eds(dcf, 1), "user --eds")}))
    # RPDO4 0x501: the log maps 6060 (8 bits) and sends 1 byte: decoded, no problem
    (r4,) = block(batch, 0x501)
    assert r4.columns == {"modes_of_operation": r4.columns["modes_of_operation"]}
    assert r4.columns["modes_of_operation"].tolist() == [0]
    # RPDO3 0x401 is not valid in the DCF and never enabled, yet frames arrive: flagged
    rows401 = np.flatnonzero(fb.can_id == 0x401)
    assert rows401.size and all(
        "not valid" in row_fields(batch, int(r))["pdo_problem"] for r in rows401
    )


def test_tmcm1636_short_pdo_against_dcf_default_mapping(tmp_path):
    # Without the log's own 0x1603 writes (DCF default: 6040/16 + 60FF/32), a 1-byte RPDO4 is short.
    dcf = real_file("nigel-bruce-khan__ros_canopen-tmcm-1636/TMCM-1636-CANopen.dcf")
    spec = NetworkSpec(
        {
            1: NodeSpec(
                load_eds(dcf, 1),
                "user --eds",
                writes=[(0x1603, 1, 0x60400010), (0x1603, 2, 0x60FF0020), (0x1603, 0, 2)],
            )
        }
    )
    _, batch = run(frames_at([(0x501, b"\x00")]), spec)
    assert batch.signals == []
    assert row_fields(batch, 0)["pdo_problem"].startswith("DLC 1 shorter than the 6 bytes mapped")


def test_roboteq_bus_yml_mapping():
    eds = real_file("jclinton830__canopen_test/roboteq_motor_controllers_v80.eds")
    fb = read_all(real_file("jclinton830__canopen_test/candump.txt"))
    _, batch = run(fb, NetworkSpec({12: NodeSpec(load_eds(eds, 12), "user --eds")}))
    (r1,) = block(batch, 0x20C)
    first = list(r1.columns.values())[0]
    assert r1.node == 12 and r1.pdo == "rpdo1" and 1000 in first.tolist()  # "E8 03" = 1000
    i = int(np.flatnonzero(first == 1000)[0])
    assert row_fields(batch, int(r1.rows[i]))["signals"][next(iter(r1.columns))] == 1000


def test_network_file_errors_name_file_and_line(tmp_path):
    bad = tmp_path / "n.yaml"
    bad.write_text(
        'nodes:\n  5:\n    device: dat7014\n    tpdo:\n      2:\n        mapping: ["6401:01/16", zz]\n'
    )
    with pytest.raises(InputError, match=r"n\.yaml:6: nodes\.5\.tpdo\.2\.mapping\.1"):
        load_network(bad)
    toml = tmp_path / "n.toml"
    toml.write_text('[nodes.5]\ndevice = "dat7014"\n[nodes.5.tpdo.2]\nevent_timer = 99999\n')
    with pytest.raises(InputError, match=r"n\.toml:4: .*out of range"):
        load_network(toml)
    toml.write_text("[nodes.5\n")
    with pytest.raises(InputError, match=r"n\.toml: .*line 1"):
        load_network(toml)
    toml.write_text('[nodes.200]\ndevice = "dat7014"\n')
    with pytest.raises(InputError, match="out of range 1..127"):
        load_network(toml)


@pytest.mark.parametrize("nodes", [(1, 2, 3), (1, 3), (2,)])
def test_bound_cob_ids_as_one_range_or_a_table_select_the_same_rows(nodes):
    """The PDO rows the decoder takes: its bound COB-IDs as one range (a wrapping compare of
    the uint32 identifiers) or, with a gap (or identifiers of another dtype), the table
    looked up by every identifier; a DBC's identifier inside the range is left to it."""
    prof = load_builtin("dat7014")
    cobs = {
        n: next(p.cob_id for p in prof.pdos(n) if p.direction == "tx" and p.valid)
        for n in (1, 2, 3)
    }
    rng = np.random.default_rng(len(nodes))
    ids = [0x080, 0x181, 0x182, *cobs.values(), 0x381, 0x701, 0x7FF]
    seq = [
        (int(rng.choice(ids)), bytes(rng.integers(0, 256, 8, dtype=np.uint8))) for _ in range(600)
    ]
    spec = NetworkSpec({n: NodeSpec(prof, "user --device") for n in nodes})
    for skip in (frozenset(), frozenset({cobs[nodes[-1]]})):
        got = []
        for wide in (False, True):
            fb = frames_at(seq)
            if wide:
                fb.can_id = fb.can_id.astype(np.int64)  # not uint32: the table's way
            model = NetworkModel(spec)
            decoder = Decoder([model, PdoDecoder(model, skip)])
            model.attach(decoder)
            batch = decoder.decode(fb)
            got.append(
                [
                    (b.cob_id, b.rows.tolist(), {k: v.tolist() for k, v in b.columns.items()})
                    for b in batch.signals
                ]
            )
        assert got[0] == got[1]
        want = sorted(cobs[n] for n in nodes if cobs[n] not in skip)
        assert sorted(c for c, _, _ in got[0]) == want
        for cob, rows, cols in got[0]:
            assert rows == [i for i, (c, _) in enumerate(seq) if c == cob]
            assert all(len(v) == len(rows) for v in cols.values())
