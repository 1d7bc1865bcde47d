"""DBC out: `devices KEY --node N --dbc OUT` and `export LOG --dbc OUT` write PDOs that
cantools loads and decodes to the values cananalyze gives for the same frames."""

from __future__ import annotations

import subprocess
import sys

import cantools
import numpy as np
import pytest

import cananalyze
from cananalyze.devices.catalog import builtin_keys
from tests.conftest import SAMPLES, real_file

TMCM = "nigel-bruce-khan__ros_canopen-tmcm-1636/"


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, check=True
    )


def _random_frames(db, rng, per: int = 60) -> list[tuple[int, bytes]]:
    out = []
    for _ in range(per):
        for msg in db.messages:
            out.append((msg.frame_id, rng.integers(0, 256, msg.length, dtype=np.uint8).tobytes()))
    return out


def _compare(cap, db, frames) -> int:
    """Every signal of the frames at the end of the log: cananalyze's value == cantools'."""
    sig = cap.signals
    checked = 0
    for msg in db.messages:
        want = [msg.decode(d, decode_choices=False) for i, d in frames if i == msg.frame_id]
        ours = sig[sig.cob_id == msg.frame_id]
        for s in msg.signals:
            got = ours[ours.signal == s.name].value.to_numpy(np.float64)
            expect = np.array([w[s.name] for w in want], np.float64)
            assert got.size >= expect.size, (msg.name, s.name)
            got = got[got.size - expect.size :]
            assert np.allclose(got, expect, rtol=1e-9, equal_nan=True), (msg.name, s.name)
            checked += got.size
    return checked


@pytest.mark.parametrize("key", builtin_keys())
def test_devices_dbc_decodes_as_cananalyze(tmp_path, key):
    out = tmp_path / f"{key}.dbc"
    text = _cli("devices", key, "--node", "5", "--dbc", str(out)).stdout
    db = cantools.database.load_file(str(out))
    assert f"wrote {len(db.messages)} PDOs of node 5 to {out}" in text
    assert db.messages and all(m.senders in ([], ["node5"]) for m in db.messages)
    frames = _random_frames(db, np.random.default_rng(len(key)))
    log = tmp_path / "bus.log"
    log.write_text(
        "".join(
            f"({k * 0.001:.6f}) can0 {i:03X}#{d.hex().upper()}\n" for k, (i, d) in enumerate(frames)
        )
    )
    cap = cananalyze.load(log, device={5: key})
    assert _compare(cap, db, frames) > 0


def test_devices_dbc_carries_scaling_units_and_sign(tmp_path):
    out = tmp_path / "d.dbc"
    _cli("devices", "dat7014", "--node", "5", "--dbc", str(out))
    db = cantools.database.load_file(str(out))
    msg = db.get_message_by_frame_id(0x285)  # TPDO2 of node 5
    ch1 = msg.get_signal_by_name("ch1")
    assert (ch1.scale, ch1.unit, ch1.is_signed, ch1.start, ch1.length) == (0.1, "°C", True, 0, 16)


def test_export_dbc_follows_the_logs_remaps(tmp_path):
    log = real_file(TMCM + "candump.txt")
    dcf = real_file(TMCM + "TMCM-1636-CANopen.dcf")
    before = tmp_path / "dcf.dbc"
    _cli("devices", str(dcf), "--node", "1", "--dbc", str(before))
    after = tmp_path / "log.dbc"
    _cli("export", str(log), "--eds", f"1={dcf}", "--dbc", str(after), "-q")
    db = cantools.database.load_file(str(after))
    # the log maps RPDO4 (0x501) to 0x6060 modes of operation alone (0x1603:01 = 0x60600008)
    rpdo4 = db.get_message_by_frame_id(0x501)
    assert [(s.name, s.start, s.length) for s in rpdo4.signals] == [("modes_of_operation", 0, 8)]
    assert rpdo4.length == 1
    dcf_db = cantools.database.load_file(str(before))
    assert {m.frame_id: [s.name for s in m.signals] for m in dcf_db.messages} != {
        m.frame_id: [s.name for s in m.signals] for m in db.messages
    }
    # frames sent after the configuration: cananalyze and cantools (with the DBC) agree
    frames = _random_frames(db, np.random.default_rng(3))
    text = log.read_text().rstrip("\n") + "\n"  # (the file ends without a newline)
    text += "".join(
        f"  can0  {i:03X}   [{len(d)}]  {' '.join(f'{b:02X}' for b in d)}\n" for i, d in frames
    )
    copy = tmp_path / "tmcm.log"
    copy.write_text(text)
    cap = cananalyze.load(copy, eds={1: dcf})
    assert _compare(cap, db, frames) >= len(frames)


def test_export_dbc_of_a_bad_destination_fails_first(tmp_path):
    log = tmp_path / "bus.log"
    log.write_text("(0.0) can0 181#00\n")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "cananalyze",
            "export",
            str(log),
            "--dbc",
            str(tmp_path / "no/x.dbc"),
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr


def test_drive_dbc_names_modes_and_commands_as_cananalyze_does(tmp_path):
    """A CiA 402 drive's DBC: cantools, decoding with its value tables, names the modes
    and the controlword's commands as cananalyze's decode does for the same frames."""
    import json

    out = tmp_path / "drive.dbc"
    _cli("devices", "cia402", "--node", "3", "--dbc", str(out))
    db = cantools.database.load_file(str(out))
    rpdo2 = db.get_message_by_frame_id(0x303)  # controlword + modes of operation
    words = {0x00: "disable voltage", 0x02: "quick stop", 0x06: "shutdown", 0x0F: "enable operation", 0x80: "fault reset"}  # fmt: skip
    frames = [(0x303, bytes([cw, 0, mode])) for cw in words for mode in (1, 3, 6, 8)]
    log = tmp_path / "drive.log"
    log.write_text(
        "".join(f"({k * 0.001:.6f}) can0 303#{d.hex()}\n" for k, (_, d) in enumerate(frames))
    )
    rows = _cli("decode", str(log), "--device", "3=cia402", "--format", "jsonl").stdout
    ours = [json.loads(r)["drive"] for r in rows.splitlines() if '"drive"' in r]
    assert len(ours) == len(frames)
    for (_, data), mine in zip(frames, ours, strict=True):
        theirs = rpdo2.decode(data)  # value tables applied
        assert str(theirs["modes_of_operation"]) == mine["modes_of_operation"]["mode"]
        # cananalyze gives the controlword's bits beside the command
        assert mine["controlword"]["command"] == str(theirs["controlword"])
    statusword = db.get_message_by_frame_id(0x183).get_signal_by_name("statusword")
    assert not statusword.choices  # states are bit patterns: no exact-value table
    # a node that is not a drive gets no drive tables on the same objects
    plain = tmp_path / "io.dbc"
    _cli("devices", "cia401", "--node", "3", "--dbc", str(plain))
    assert "disable voltage" not in plain.read_text(encoding="cp1252")


def test_export_dbc_carries_the_dbc_the_log_was_decoded_with(tmp_path):
    """`export --dbc-in MINE --dbc OUT`: OUT holds the user's messages as they were
    (non-CANopen identifiers, and a PDO the user's DBC redefines) beside the PDOs."""
    from tests.devices.test_dbc_in import MIXED_DBC

    mine = tmp_path / "mine.dbc"
    mine.write_text(MIXED_DBC)
    log = tmp_path / "bus.log"
    log.write_text(
        "(0.000) can0 000#0100\n(0.010) can0 185#0100020003000400\n"
        "(0.020) can0 10A#0102030405060708\n(0.030) can0 1A5#0100020003000400\n"
    )
    out = tmp_path / "out.dbc"
    _cli(
        "export", str(log), "--device", "5=dat7014", "--dbc-in", str(mine), "--dbc", str(out), "-q"
    )
    db = cantools.database.load_file(str(out))
    user = cantools.database.load_file(str(mine))
    for msg in user.messages:  # every message of the user's DBC, unchanged
        got = db.get_message_by_frame_id(msg.frame_id)
        assert got.name == msg.name
        assert sorted(
            (s.name, s.start, s.length, s.scale, s.is_signed) for s in got.signals
        ) == sorted((s.name, s.start, s.length, s.scale, s.is_signed) for s in msg.signals)
    # 0x1A5 is node 37's TPDO2 by the predefined set, but the user's "Drive" wins, as in decoding
    assert db.get_message_by_frame_id(0x1A5).name == "Drive"
    # node 5's own PDOs are there too
    assert db.get_message_by_frame_id(0x285).name == "node5_TPDO2"


def test_a_dbc_of_no_message_is_a_warning(tmp_path):
    """A log whose nodes no profile, EDS or network file names: the DBC has no message
    (cantools reads none), which the user hears about; --strict makes it exit 1."""
    log = real_file("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log")
    out = tmp_path / "none.dbc"
    run = [sys.executable, "-m", "cananalyze", "export", str(log), "--dbc", str(out), "-q"]
    r = subprocess.run(run, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0
    assert len(cantools.database.load_file(str(out)).messages) == 0
    assert f"warning: {out}: DBC with no message" in r.stderr
    assert subprocess.run([*run, "--strict"], capture_output=True, timeout=120).returncode == 1
    # a log with known devices: messages, no warning
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", str(SAMPLES / "demo.log")]
        + ["--dbc", str(out), "-q"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0 and "no message" not in r.stderr
    assert len(cantools.database.load_file(str(out)).messages) > 0


def test_devices_dbc_written_when_the_reader_stops_early(tmp_path):
    """Issue 44 item 6: `devices EDS --dbc out.dbc | head -1` wrote no DBC (it was written
    after printing, and the closed pipe ended the run first). The DBC comes first now."""
    import os

    from tests.conftest import ROOT

    eds = real_file("christiansandberg__canopen/sample.eds")
    out = tmp_path / "out.dbc"
    proc = subprocess.Popen(
        [sys.executable, "-m", "cananalyze", "devices", str(eds), "--dbc", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert proc.stdout.readline()  # what `head -1` reads
    proc.stdout.close()  # and then it exits
    proc.wait(timeout=120)
    assert b"Traceback" not in proc.stderr.read()
    db = cantools.database.load_file(str(out))
    assert db.messages  # the EDS's default PDOs
