"""Built-in device profiles decode the manuals' own frames to the manuals' meanings,
and any real EDS/DCF loads through canopen with its identity and PDO mappings."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import real_file, seed_file

from cananalyze.core.errors import InputError
from cananalyze.devices.builtin import builtin_profiles, identify, load_builtin
from cananalyze.devices.profile import load_eds
from cananalyze.protocol.pdo import decode_pdo


def decode_one(mapping, payload: bytes):
    data = np.zeros((1, 8), np.uint8)
    data[0, : len(payload)] = list(payload)
    out = decode_pdo(data, np.array([len(payload)]), mapping)
    return {k: v[0].item() for k, v in out.values.items()}, out


def pdo(profile, direction, number, node):
    return next(p for p in profile.pdos(node) if p.direction == direction and p.number == number)


def emcy(profile, frame: str):
    raw = bytes.fromhex(frame)
    return profile.decode_emcy(int.from_bytes(raw[:2], "little"), raw[2], raw[3:])


def test_builtins_identity_from_manuals():
    by_key = {p.key: p for p in builtin_profiles()}
    assert set(by_key) == {"dat7130", "dat7014", "i7231d", "mcb560"}
    assert (by_key["dat7130"].vendor_id, by_key["dat7130"].product_code) == (0x3CD, 7)
    assert by_key["dat7130"].device_type == 0x00030191
    assert (by_key["dat7014"].vendor_id, by_key["dat7014"].product_code) == (0x3CD, 2)
    assert by_key["mcb560"].vendor_id == 0x58
    assert by_key["mcb560"].product_code == 0x01420100
    assert by_key["mcb560"].device_name == "CO4201"
    assert by_key["i7231d"].device_name == "CPS_DCON"
    for p in by_key.values():
        assert p.notes and p.source.endswith(f"{p.key}.eds")
        assert any("100 us" in n for n in p.notes)


def test_identify_from_sdo_uploads():
    assert identify(vendor_id=0x3CD, product_code=7).key == "dat7130"
    assert identify(vendor_id=0x3CD, product_code=2, device_name="DAT 7014").key == "dat7014"
    assert identify(vendor_id=0x58, product_code=0x01420100).key == "mcb560"
    assert identify(device_name="CO4201").key == "mcb560"
    # the manual's SDO upload demo reads 0x1008 = "CPS_DCON" (43 50 53 5F 44 43 4F 4E)
    assert identify(device_name=bytes.fromhex("4350535F44434F4E").decode()).key == "i7231d"
    assert identify(vendor_id=0x3CD) is None  # both Datexel devices: ambiguous
    assert identify(vendor_id=0x3CD, product_code=99) is None
    assert identify(device_type=0x00030191) is None  # shared by many CiA 401 devices
    assert identify(vendor_id=0x3CD, product_code=7, device_name="DAT 7014") is None


def test_dat7130_default_pdos_and_frames():
    seed_file("000_4009fcd801cdb781.txt")
    prof = load_builtin("dat7130")
    pdos = prof.pdos(0x10)
    assert [(p.direction, p.number, p.cob_id) for p in pdos] == [
        ("rx", 1, 0x210),
        ("tx", 1, 0x190),
        ("tx", 2, 0x290),
        ("tx", 3, 0x390),
        ("tx", 4, 0x490),
    ]
    assert all(p.valid and p.transmission_type == 0xFF for p in pdos)
    t1 = pdo(prof, "tx", 1, 0x10)
    values, _ = decode_one(t1.mapping, bytes([0b10000101]))
    assert values == {f"di{i}": i in (1, 3, 8) for i in range(1, 9)}
    t3 = pdo(prof, "tx", 3, 0x10)
    values, _ = decode_one(t3.mapping, bytes.fromhex("0100000010270000"))
    assert values == {"counter3": 1, "counter4": 10000}
    assert t3.mapping[0].datatype == 0x07 and t3.mapping[0].unit == "pulses"
    r1 = pdo(prof, "rx", 1, 0x10)
    values, _ = decode_one(r1.mapping, bytes([0xFA]))  # high nibble is not an output
    assert values == {"do1": False, "do2": True, "do3": False, "do4": True}
    assert prof.object(0x1018, 1).default == 0x3CD
    assert prof.object(0x1800, 3).name == "Inhibit time"


def test_dat7014_units_follow_sensor_type():
    prof = load_builtin("dat7014")
    pdos = prof.pdos(5)
    assert [(p.direction, p.number, p.cob_id) for p in pdos] == [("tx", 2, 0x285)]
    mapping = pdos[0].mapping
    assert [(e.index, e.subindex, e.bits, e.datatype) for e in mapping] == [
        (0x6401, s, 16, 0x03) for s in (1, 2, 3, 4)
    ]
    # default sensor type 0x12 (Pt100): tenths of a degree
    values, _ = decode_one(mapping, bytes.fromhex("EA00 0CFE 0000 E803"))
    assert values == pytest.approx({"ch1": 23.4, "ch2": -50.0, "ch3": 0.0, "ch4": 100.0})
    assert prof.signal_meta(0x6401, 1, {}) == ("ch1", "°C", 0.1, 0.0)
    ctx = {(0x2107, 1): 0x11, (0x2107, 2): 0x10, (0x2107, 3): 0x16, (0x2107, 4): 0x13}
    assert prof.signal_meta(0x6401, 1, ctx)[1:3] == ("Ω", 0.1)
    assert prof.signal_meta(0x6401, 2, ctx)[1:3] == ("Ω", 1.0)
    assert prof.signal_meta(0x6401, 3, ctx)[1:3] == ("%", 0.1)
    assert prof.signal_meta(0x6401, 4, ctx)[1:3] == ("°C", 0.1)
    assert prof.signal_meta(0x6401, 1, {(0x2107, 1): 0})[1:3] == (None, None)
    remapped = prof.pdos(5, ctx)[0].mapping
    values, _ = decode_one(remapped, bytes.fromhex("EA00 0CFE 0000 E803"))
    assert values == pytest.approx({"ch1": 23.4, "ch2": -500.0, "ch3": 0.0, "ch4": 100.0})


def test_mcb560_default_pdos():
    prof = load_builtin("mcb560")
    tx = {p.number: p for p in prof.pdos(0x22) if p.direction == "tx"}
    assert tx[1].cob_id == 0x1A2 and tx[2].cob_id == 0x2A2 and tx[3].cob_id == 0x3A2
    assert not tx[5].valid and tx[5].transmission_type == 1
    assert [e.bits for e in tx[1].mapping] == [8, 8, 8, 8]
    values, _ = decode_one(tx[1].mapping, bytes([0x81, 0, 0, 0]))
    assert values["inputs_7_0"] == 0x81
    # analog inputs in mV, INTEGER16: 2500 mV, 0, 5000 mV, 1 mV
    values, _ = decode_one(tx[2].mapping, bytes.fromhex("C409 0000 8813 0100"))
    assert values == {"analog0": 2500, "analog1": 0, "analog2": 5000, "analog3": 1}
    assert {e.unit for e in tx[2].mapping} == {"mV"}
    assert [e.name for e in tx[3].mapping] == ["analog4", "analog5", "analog6", "analog7"]


# Every emergency frame printed in the MCB-560 manual, section 4.9 (bytes 0..7).
MCB_FRAMES = [
    ("30 81 01 00 00 00 00 10", 0x10000000, ["heartbeat error"], "heartbeat error"),
    ("30 81 01 00 00 00 00 20", 0x20000000, ["node guarding warning"], "node-guarding warning"),
    ("30 81 11 00 00 00 00 30", 0x30000000, ["life guarding error"], "life-guarding error"),
    ("10 23 01 00 01 00 00 00", 0x00000001, ["output overload"], "output overload"),
    ("00 81 01 00 00 00 00 40", 0x40000000, ["error warning"], "CAN bus in error warning"),
    (
        "40 81 01 00 00 00 00 C0",
        0xC0000000,
        ["bus off", "error warning"],
        "return from CAN bus off",
    ),
]


@pytest.mark.parametrize("frame,chip_ec,flags,meaning", MCB_FRAMES)
def test_mcb560_emcy_frames_from_manual(frame, chip_ec, flags, meaning):
    seed_file("004_b12e0f30c6bded9a.txt")
    got = emcy(load_builtin("mcb560"), frame)
    assert got["chip_ec"] == chip_ec
    assert got["flags"] == flags
    assert got["meaning"].startswith(meaning)


def test_mcb560_chip_ec_or_combination_and_wakeup():
    prof = load_builtin("mcb560")
    got = prof.decode_emcy(0x8100, 0x11, bytes([0, 0x01, 0, 0, 0xB0]))  # 0xB0000001
    assert got["flags"] == ["bus off", "life guarding error", "output overload"]
    assert "meaning" not in got
    assert prof.decode_emcy(0x0000, 0, bytes(5))["flags"] == ["wake up from power down"]
    assert prof.decode_emcy(0x8130, 0x11, b"\x00") is None  # manufacturer field too short


def test_i7231d_emcy_examples():
    seed_file("002_8af3d3370e33cdbc.txt")
    prof = load_builtin("i7231d")
    # EMCY demo: RS-485 wire to module 01 cut -> 00 FF 81 0B 01 00 00 00 on COB-ID 0x81
    got = emcy(prof, "00 FF 81 0B 01 00 00 00")
    assert got["vendor_code"] == 0x0B and got["module_address"] == 1
    assert "RS-485 module 0x01 timed out" in got["meaning"]
    # node guarding demo: 30 81 11 07 00 00 00 00 = life guard error
    got = emcy(prof, "30 81 11 07 00 00 00 00")
    assert got["vendor_code"] == 7 and got["meaning"] == "life guarding fails"
    assert emcy(prof, "00 00 00 00 00 00 00 00")["meaning"] == "error reset or no error"
    assert emcy(prof, "10 82 11 09 00 00 00 00")["meaning"] == "PDO data length error"


def test_i7231d_pdo_demo_frames():
    seed_file("002_8af3d3370e33cdbc.txt")
    prof = load_builtin("i7231d")
    pdos = prof.pdos(1)
    t1 = pdo(prof, "tx", 1, 1)
    assert t1.cob_id == 0x181
    # Step 44: TPDO1 0x181 L=3 "54 6F 01": DI0-7 and DI8-15 of the I-7053D, DI0 of the I-7012D
    values, out = decode_one(t1.mapping, bytes.fromhex("546F01"))
    assert values == {"di_byte1": 0x54, "di_byte2": 0x6F, "di_byte3": 0x01}
    assert not out.short[0]
    # The dynamic-mapping demo builds the 5th TPDO (COB-ID 0x182) from 0x1A05 =
    # 6000:01/8, 6000:02/8, 6401:01/16 and receives "54 6F 06 00" (L=4)
    mapping = []
    for word in (0x60000108, 0x60000208, 0x64010110):
        mapping += prof.map_entries(word >> 16, (word >> 8) & 0xFF, word & 0xFF)
    values, out = decode_one(mapping, bytes.fromhex("546F0600"))
    assert (values["di_byte1"], values["di_byte2"]) == (0x54, 0x6F)
    assert values["ai0_i7012"] == pytest.approx(0.002, abs=5e-4)  # "the AI0 value is 0.002V"
    assert not out.short[0] and not out.extra[0]
    # TPDO2 0x281 "F5 3F" (L=2): 0x3FF5 -> 4.997 V by the manual's formula
    values, _ = decode_one(pdo(prof, "tx", 2, 1).mapping, bytes.fromhex("F53F"))
    assert values["ai0_i7012"] == pytest.approx(4.997, abs=5e-4)
    # RPDO2 0x301 "FF 07 00 00 00 00 00 00": AO0 of the I-7021 = 5 V; only 2 bytes mapped
    r2 = pdo(prof, "rx", 2, 1)
    assert r2.cob_id == 0x301
    values, out = decode_one(r2.mapping, bytes.fromhex("FF07000000000000"))
    assert values["ao0_i7021"] == pytest.approx(5.0, abs=2e-3) and out.extra[0]
    assert not next(p for p in pdos if p.direction == "tx" and p.number == 5).valid


def test_load_eds_axiomatic_identity_and_pdos():
    prof = load_eds(real_file("calumroy__CANopen_socketCAN_Test/EDS-23123-1.01.eds"))
    assert prof.vendor_id == 0x55
    assert prof.product_code == 0xAA020421
    assert prof.notes == [] and prof.sidecar is None
    tx1 = pdo(prof, "tx", 1, 0x7F)
    assert tx1.cob_id == 0x1FF and tx1.valid
    assert [(e.index, e.subindex, e.bits) for e in tx1.mapping] == [
        (0x7100, s, 16) for s in (1, 2, 3, 4)
    ]
    assert prof.object(0x7100, 1).datatype == 0x03


def test_load_dcf_values_take_precedence():
    prof = load_eds(real_file("nigel-bruce-khan__ros_canopen-tmcm-1636/TMCM-1636-CANopen.dcf"))
    assert prof.vendor_id == 0x286
    assert prof.device_name == "TMCM-1636"
    tx = {p.number: p for p in prof.pdos(1) if p.direction == "tx"}
    # DCF ParameterValue 1073742209 = 0x40000181: valid, no RTR, identifier 0x181
    assert tx[1].cob_id == 0x181 and tx[1].valid
    assert [(e.index, e.bits) for e in tx[1].mapping] == [(0x6041, 16), (0x6061, 8)]
    assert tx[3].transmission_type == 1
    rx = {p.number: p for p in prof.pdos(1) if p.direction == "rx"}
    assert [(e.index, e.bits) for e in rx[1].mapping] == [(0x6040, 16), (0x60FF, 32)]
    assert not rx[3].valid


def test_load_other_real_files():
    roboteq = load_eds(real_file("jclinton830__canopen_test/roboteq_motor_controllers_v80.eds"))
    assert roboteq.vendor_id == 0x469
    assert pdo(roboteq, "tx", 1, 12).cob_id == 0x18C
    sample = load_eds(real_file("christiansandberg__canopen/sample.eds"))
    assert sample.node_id == 16 and pdo(sample, "tx", 1, None).cob_id == 0x190
    datatypes = load_eds(real_file("christiansandberg__canopen/datatypes.eds"))
    assert datatypes.pdos(1) == [] or all(not p.mapping for p in datatypes.pdos(1))
    c3 = load_eds(real_file("oresat__CANopen-monitor/c3.dcf"))
    assert c3.device_name == "OreSat C3"
    r1 = pdo(c3, "rx", 1, None)
    assert [(e.index, e.bits, e.datatype) for e in r1.mapping] == [(0x2010, 64, 0x1B)]
    battery = load_eds(real_file("oresat__CANopen-monitor/battery.dcf"))
    assert battery.device_name == "OreSat Battery"


def test_bad_eds_is_one_line_input_error(tmp_path):
    bad = tmp_path / "broken.eds"
    bad.write_text("[1000]\nParameterName=Device type\nDataType=0x0007\n[1000\n")
    with pytest.raises(InputError) as exc:
        load_eds(bad)
    assert "broken.eds" in str(exc.value) and "\n" not in str(exc.value)
    with pytest.raises(InputError, match="no such"):
        load_eds(tmp_path / "missing.eds")
    other = tmp_path / "notes.txt"
    other.write_text("x")
    with pytest.raises(InputError, match="not an EDS"):
        load_eds(other)
    with pytest.raises(InputError, match="unknown device profile"):
        load_builtin("nope")


def test_devices_cli(capsys):
    import argparse

    from cananalyze.cli import devices

    parser = argparse.ArgumentParser()
    devices.add_parser(parser.add_subparsers())
    args = parser.parse_args(["devices"])
    assert args.func(args) == 0
    listing = capsys.readouterr().out
    assert all(k in listing for k in ("dat7130", "dat7014", "i7231d", "mcb560"))
    assert "0x000003CD" in listing and "0x01420100" in listing
    args = parser.parse_args(["devices", "mcb560", "--node", "5"])
    assert args.func(args) == 0
    shown = capsys.readouterr().out
    assert "TPDO2 COB-ID 0x285" in shown and "analog0 [mV]" in shown and "Notes:" in shown
