"""CiA 402 drives: the tables against python-canopen's, real drive files, and a drive and
master of python-canopen's on a virtual bus."""

from __future__ import annotations

import logging
import subprocess
import sys

import numpy as np
import pytest
from canopen.profiles.p402 import OperationMode, State402

import cananalyze
from cananalyze.devices import cia401, cia402
from cananalyze.devices.builtin import load_builtin
from cananalyze.devices.profile import load_eds
from tests.conftest import real_file
from tests.helpers.drive402 import STATUSWORD, Drive402
from tests.helpers.virtual_bus import unique_channel

TMCM = "nigel-bruce-khan__ros_canopen-tmcm-1636/"
ZEROERR = "SeonilChoi__CANOPEN-SDK/"
SLAVE_EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"


def _p402_state(word: int) -> str | None:
    """python-canopen's BaseNode402.state for a statusword (its mask table, in its order)."""
    for state, (mask, value) in State402.SW_MASK.items():
        if word & mask == value:
            return state
    return None


def test_every_statusword_names_the_state_python_canopen_names():
    words = np.arange(0x10000)
    ours = cia402.state_codes(words)
    for w in range(0x10000):
        theirs = _p402_state(w)
        got = cia402.STATE_NAMES[ours[w]]
        assert got == (theirs.lower() if theirs else "unknown state"), hex(w)


def test_the_transition_table_holds_python_canopens_transitions():
    """Each transition p402 commands is allowed, and its controlword leads there."""
    for (src, dst), word in State402.TRANSITIONTABLE.items():
        if src == "START":
            continue
        a, b = cia402.STATE_NAMES.index(src.lower()), cia402.STATE_NAMES.index(dst.lower())
        assert (a, b) in cia402.TRANSITIONS, (src, dst)
        if src in ("NOT READY TO SWITCH ON", "FAULT REACTION ACTIVE"):
            continue  # automatic transitions (1, 14): no command
        cmd = int(cia402.command_codes(np.array([word]))[0])
        if cmd == cia402.SWITCH_ON and a == cia402.OPERATION_ENABLED:
            cmd = cia402.DISABLE_OPERATION
        assert cia402.COMMAND_TARGET[(cmd, a)] == b, (src, dst, hex(word))


def test_modes_of_operation_by_name():
    for code, name in OperationMode.CODE2NAME.items():
        assert cia402.mode_text(code).replace("profile", "profiled") == name.lower()
    assert cia402.mode_text(-1) == "manufacturer-specific mode -1"


def test_words_of_statusword_and_controlword():
    assert cia402.statusword_text(0x0227) == "operation enabled; remote"
    assert cia402.statusword_text(0x0618) == "fault; voltage enabled, remote, target reached"
    assert cia402.statusword_text(0x1C27) == (
        "operation enabled; target reached, internal limit active, set-point acknowledge"
    )
    assert cia402.controlword_text(0x0006).startswith("shutdown;")
    assert cia402.command_name(0x0007, cia402.OPERATION_ENABLED) == "disable operation"
    assert cia402.command_name(0x0080) == "fault reset"
    assert cia402.command_name(0x0002) == "quick stop"
    assert cia402.command_name(0x0000) == "disable voltage"


@pytest.mark.parametrize(
    "path",
    [
        TMCM + "TMCM-1636-CANopen.dcf",
        ZEROERR + "ZeroErr_Driver_V1.5.eds",
        ZEROERR + "elmo.dcf",
        "dianhuaeven__Eyou_Canopen_master/YiyouServo_V1.4.eds",
        SLAVE_EDS,
        "KITmedical__kacanopen_old/605.3150.68-B-EK-2-60.eds",
        "Qiaoqiao23333__tower_crane/DSY-C.eds",
    ],
)
def test_real_drive_files_are_cia402_with_units(path):
    prof = load_eds(real_file(path), 1)
    assert prof.family == 402
    name, unit, _, _ = prof.signal_meta(0x6064, 0)
    assert name == "position_actual_value" and unit == "inc"
    assert prof.signal_meta(0x6077, 0)[1] == "‰ rated torque"


def test_generic_402_profile_has_the_standard_default_pdos():
    prof = load_builtin("cia402")
    pdos = {(p.direction, p.number): p for p in prof.pdos(7)}
    assert pdos[("tx", 1)].cob_id == 0x187 and [e.index for e in pdos[("tx", 1)].mapping] == [
        0x6041
    ]
    assert [e.index for e in pdos[("rx", 1)].mapping] == [0x6040]
    assert [e.index for e in pdos[("tx", 3)].mapping] == [0x6041, 0x6064]
    assert pdos[("rx", 4)].cob_id == 0x507
    assert prof.object(0x607A, 0).name == "Target position"  # the EDS ParameterName style


def _log(frames, path) -> str:
    with open(path, "w") as f:
        for t, cob, data in frames:
            f.write(f"({t:.6f}) vcan0 {cob:03X}#{data.hex().upper()}\n")
    return str(path)


def _drive_run(tmp_path, refuse=(), steps=("OPERATION ENABLED", "SWITCH ON DISABLED"), fault=True):
    logging.getLogger("canopen").setLevel(logging.ERROR)
    d = Drive402(str(real_file(SLAVE_EDS)), 5, unique_channel("p402"), refuse=set(refuse))
    failed = []
    try:
        d.master.setup_402_state_machine(read_pdos=False)
        assert d.master.sdo[0x1000].raw == 0x00060192  # the master asks the device type
        d.master.TIMEOUT_SWITCH_STATE_FINAL = 0.6
        for target in steps:
            try:
                d.master.state = target
            except RuntimeError as exc:
                failed.append(str(exc))
        if fault:
            d.fault(0x2310)
            assert d.master.state == "FAULT"
        return _log(d.frames(), tmp_path / "p402.log"), failed
    finally:
        d.close()


@pytest.mark.slow
def test_python_canopen_drive_states_and_a_fault(tmp_path):
    log, failed = _drive_run(tmp_path)
    assert not failed
    cap = cananalyze.load(log)  # no EDS: the 0x1000 read names CiA 402
    assert cap.profiles[5][0] == "cia402"
    states = cap.drive_states
    assert states.state.tolist() == [
        "switch on disabled",
        "ready to switch on",
        "switched on",
        "operation enabled",
        "switch on disabled",
        "fault",
    ]
    assert set(states.source) == {"sdo"}
    assert cap.drive_commands.command.tolist()[:3] == ["shutdown", "switch on", "enable operation"]
    f = cap.findings
    drive = f[f.rule.str.startswith("drive_")]
    assert drive.rule.tolist() == ["drive_fault"]
    assert "EMCY 0x2310" in drive.message.iloc[0]
    ev = cap.events[cap.events.kind == "drive_state"]
    assert "operation enabled" in " ".join(ev.message)
    # the SDO text names the words too (with the drive's EDS: named from the first batch on)
    eds = f"5={real_file(SLAVE_EDS)}"
    text = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", log, "--eds", eds],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "Status word expedited -> ok: 551 (0x227) (operation enabled; remote)" in text
    assert "Control word expedited -> ok: 15 (0xF) (enable operation; " in text


@pytest.mark.slow
def test_a_command_the_drive_does_not_follow(tmp_path):
    log, failed = _drive_run(
        tmp_path, refuse={"OPERATION ENABLED"}, steps=("OPERATION ENABLED",), fault=False
    )
    assert failed  # python-canopen gave up waiting
    rules = tmp_path / "rules.yaml"
    rules.write_text("rules:\n  drive_command: {timeout_ms: 200}\n")
    f = cananalyze.load(log, rules=str(rules)).findings
    cmd = f[f.rule == "drive_command"]
    assert len(cmd) == 1
    msg = cmd.message.iloc[0]  # the evidence: the statuswords it kept reading by SDO
    assert "drive not operation enabled 200.0 ms after enable operation" in msg
    assert "; still switched on at +" in msg
    # with the default (1 s) the master's 0.6 s wait shows no evidence: nothing judged
    f = cananalyze.load(log).findings
    assert (f.rule == "drive_command").sum() == 0


def test_tmcm_1636_fault_read_by_sdo_and_a_later_emcy_not_blamed():
    """A log without times: the fault read at line 14 is not the EMCY 0x6320 the drive
    sends 88 lines later, after a parameter write (issue 44); the EMCY is its own finding."""
    log = real_file(TMCM + "candump.txt")
    cap = cananalyze.load(log, eds={1: str(real_file(TMCM + "TMCM-1636-CANopen.dcf"))})
    assert cap.drive_states.state.tolist() == ["fault"]
    assert cap.drive_states.statusword.tolist() == [0x0618]
    assert cap.drive_commands.command.tolist() == ["disable voltage", "fault reset"]
    f = cap.findings
    fault = f[f.rule == "drive_fault"].message.tolist()
    assert fault == ["drive entered fault (statusword 0x0618) (no EMCY from the node around it)"]
    emcy = f[f.rule == "emcy"].message.tolist()
    assert len(emcy) == 1 and "EMCY 0x6320" in emcy[0]


def test_zeroerr_log2_enable_sequence_from_remapped_tpdo1():
    log = real_file(ZEROERR + "log2.txt")
    for kw in ({"eds": {11: str(real_file(ZEROERR + "ZeroErr_Driver_V1.5.eds"))}},
               {"device": {11: "cia402"}}):  # fmt: skip
        cap = cananalyze.load(log, **kw)
        assert cap.drive_states.state.tolist() == [
            "switch on disabled",
            "ready to switch on",
            "switched on",
            "operation enabled",
        ], kw
        assert cap.drive_states.statusword.tolist()[-1] == 567
        assert cap.drive_commands.command.tolist() == [
            "shutdown",
            "switch on",
            "enable operation",
            "quick stop",
        ]
        sig = cap.signals
        pos = sig[sig.signal == "position_actual_value"]
        assert len(pos) > 500 and set(pos.unit) == {"inc"}  # TPDO1 remapped: 6041 + 6064
        f = cap.findings
        assert not f.rule.str.startswith("drive_").any()


def test_cia401_defaults_decode_a_short_module(tmp_path):
    log = _log([(0.0, 0x183, bytes([0x05, 0x80])), (0.1, 0x283, bytes([0x10, 0x00]))],
               tmp_path / "io.log")  # fmt: skip
    cap = cananalyze.load(log, device={3: "cia401"})
    got = dict(zip(cap.signals.signal, cap.signals.value, strict=True))
    assert got == {"digital_inputs_1_8": 5, "digital_inputs_9_16": 0x80, "analog_input_1": 16}
    assert not (cap.findings.rule == "pdo_length").any()  # the defaults are not the device's
    assert cia401.DEFAULT_PDOS[("rx", 2)][0] == (0x6411, 1)


@pytest.mark.parametrize("arg", ["0=cia402", "5=cia999", "x=cia402"])
def test_bad_device_is_one_line(tmp_path, arg):
    log = _log([(0.0, 0x181, b"\x37\x06")], tmp_path / "d.log")
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", log, "--device", arg],
        capture_output=True,
        text=True,
    )
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_drive_state_lanes_in_mcap_rerun_and_the_event_tables(tmp_path):
    """Read back by the mcap package, rerun's reader and pyarrow, not by our code."""
    import json

    import pyarrow.parquet as pq
    from mcap.reader import make_reader

    from tests.exported import read_rrd

    log = str(real_file(ZEROERR + "log2.txt"))
    out = tmp_path / "out"
    subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", log, "--device", "11=cia402", "-q",
         "--mcap", str(tmp_path / "x.mcap"), "--rrd", str(tmp_path / "x.rrd"),
         "--parquet", str(out)],
        check=True,
    )  # fmt: skip
    expected = ["switch on disabled", "ready to switch on", "switched on", "operation enabled"]
    with open(tmp_path / "x.mcap", "rb") as f:
        msgs = [
            json.loads(m.data)
            for _, _, m in make_reader(f).iter_messages(topics=["/node/11/drive_state"])
        ]
    assert [m["state"] for m in msgs] == expected and msgs[-1]["statusword"] == 567
    rrd = read_rrd(tmp_path / "x.rrd")
    lane = rrd.rows["/node/11/drive_state"]  # this log has no times: in sent order
    assert [r["StateChange:state"][0] for r in lane] == expected
    assert any("/node/11/drive_state" in repr(view) for view in rrd.layout)
    events = pq.read_table(out / "events.parquet").to_pandas()
    drive = events[events.kind == "drive_state"]
    assert drive.message.iloc[-1].startswith("node 11: drive state operation enabled")
    sdo = pq.read_table(out / "sdo.parquet").to_pandas()
    keys = zip(sdo["index"], sdo["subindex"], strict=True)
    words = dict(zip(keys, sdo["words"], strict=True))
    assert words[(0x1A00, 1)] == "6041:00, 16 bit, Statusword"
    assert words[(0x1A00, 2)] == "6064:00, 32 bit, Position actual value"
    assert words[(0x1800, 1)].startswith("COB-ID 0x18B, ")
    assert words[(0x6060, 0)].endswith("position")


def test_config_words_in_jsonl_are_an_added_field(tmp_path):
    import json

    log = real_file(TMCM + "candump.txt")
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--sdo", "--format", "jsonl"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    recs = [json.loads(line) for line in out.splitlines()]
    sdo = [r for r in recs if r.get("kind") == "sdo"]
    by = {(r["index"], r["subindex"], r["direction"], r["data"]): r for r in sdo}
    r = by[(0x1800, 1, "download", "810100c0")]
    assert r["words"] == "COB-ID 0x181, not valid, no RTR, 11-bit"
    assert r["value"] == 0xC0000181 and r["name"]  # the other fields as they were
    assert by[(0x1A00, 1, "download", "10004160")]["words"] == "6041:00, 16 bit"
    assert by[(0x1017, 0, "download", "0000")]["words"] == "off"


@pytest.mark.parametrize("ttype, judged", [(0xFF, True), (0xFE, True), (0x01, False)])
def test_a_jump_the_state_machine_does_not_have(tmp_path, ttype, judged):
    """Switch on disabled straight to operation enabled: a finding only when the TPDO
    (transmission type written by SDO in the log) sends every change."""
    frames = [
        (0.00, 0x601, bytes([0x2F, 0x00, 0x18, 0x02, ttype, 0, 0, 0])),  # 0x1800:02 = ttype
        (0.01, 0x581, bytes([0x60, 0x00, 0x18, 0x02, 0, 0, 0, 0])),
        (0.10, 0x181, bytes([0x40, 0x02])),  # switch on disabled
        (0.20, 0x201, bytes([0x0F, 0x00])),  # enable operation, no shutdown / switch on
        (0.30, 0x181, bytes([0x27, 0x02])),  # operation enabled
        (0.40, 0x181, bytes([0x27, 0x02])),
    ]
    log = _log(frames, tmp_path / "jump.log")
    f = cananalyze.load(log, device={1: "cia402"}).findings
    jump = f[f.rule == "drive_transition"]
    if judged:
        (msg,) = jump.message
        assert "from switch on disabled to operation enabled" in msg and "TPDO1" in msg
    else:  # a synchronous TPDO samples the state: two transitions may fall between
        assert jump.empty
    # the same steps one at a time are no finding
    steps = [(0.1 * k, 0x181, bytes([w, 0x02])) for k, w in enumerate((0x40, 0x21, 0x23, 0x27))]
    ok = cananalyze.load(_log(frames[:2] + steps, tmp_path / "ok.log"), device={1: "cia402"})
    assert not (ok.findings.rule == "drive_transition").any()


def test_network_file_device_cia402(tmp_path):
    net = tmp_path / "net.toml"
    net.write_text('[nodes.11]\ndevice = "cia402"\n')
    cap = cananalyze.load(real_file(ZEROERR + "log2.txt"), network=str(net))
    assert cap.drive_states.state.tolist()[-1] == "operation enabled"
    net.write_text('[nodes.11]\ndevice = "cia403"\n')
    with pytest.raises(cananalyze.InputError, match=r"net.toml:2: .*unknown device 'cia403'"):
        cananalyze.load(real_file(ZEROERR + "log2.txt"), network=str(net))


def test_unknown_data_as_text_only_beyond_expedited():
    """One in 50 random 4-byte values is printable ASCII: expedited data of an unknown type
    is never worded as text; a segmented transfer's string is."""
    from cananalyze.devices.object_words import object_words, visible_string

    assert visible_string(b"AB12") is None and visible_string(b"Ab") is None
    assert object_words(0x2000, 0, None, b"MyDrive v1.2\x00\x00") == 'text "MyDrive v1.2"'
    assert object_words(0x2000, 0, None, b"\x01\x02\x03\x04\x05") is None
    assert object_words(0x2000, 0, 7, b"Hello world") is None  # typed: the value says it


def _self_enabling_run(tmp_path, jump: str | None) -> str:
    """python-canopen's master walks its drive to operation enabled and back to switch on
    disabled by SDO; then (jump) the drive moves to `jump` by itself and the master reads
    its statusword."""
    logging.getLogger("canopen").setLevel(logging.ERROR)
    d = Drive402(str(real_file(SLAVE_EDS)), 5, unique_channel("p402self"))
    try:
        d.master.setup_402_state_machine(read_pdos=False)
        assert d.master.sdo[0x1000].raw == 0x00060192  # names the drive CiA 402
        d.master.TIMEOUT_SWITCH_STATE_FINAL = 2.0
        for target in ("OPERATION ENABLED", "SWITCH ON DISABLED"):
            d.master.state = target
        if jump is not None:
            d._set(jump)  # no controlword: the drive moves on its own
        assert d.master.sdo[0x6041].raw in (STATUSWORD[jump or "SWITCH ON DISABLED"],)
        return _log(d.frames(), tmp_path / "self.log")
    finally:
        d.close()


@pytest.mark.parametrize("jump", ["OPERATION ENABLED", "READY TO SWITCH ON"])
def test_a_drive_that_enables_itself_without_a_command(tmp_path, jump):
    """The statusword is polled by SDO (states may be skipped between reads), but the
    controlwords are on the bus: a drive reaching an enabled state with no command that
    leads there is a finding, naming the command in force and those sent since."""
    log = _self_enabling_run(tmp_path, jump)
    f = cananalyze.load(log).findings  # the 0x1000 read names CiA 402
    jumps = f[f.rule == "drive_transition"]
    (msg,) = jumps.message
    name = jump.lower()
    assert msg.startswith(f"drive went from switch on disabled to {name} (statusword 0x")
    assert "in SDO) without a command that leads there: in force disable voltage" in msg
    assert msg.endswith("sent since: none")
    assert jumps.severity.iloc[0] == "error" and jumps.node.iloc[0] == 5


def test_the_enable_sequence_by_sdo_is_no_finding(tmp_path):
    log = _self_enabling_run(tmp_path, None)
    cap = cananalyze.load(log)
    assert cap.drive_states.state.tolist() == [
        "switch on disabled",
        "ready to switch on",
        "switched on",
        "operation enabled",
        "switch on disabled",
    ]
    assert not cap.findings.rule.str.startswith("drive_").any()


@pytest.mark.slow
def test_fault_and_its_emcy_paired_in_a_log_without_times(tmp_path):
    """python-canopen's drive faults (EMCY 0x2310, then fault); the log printed as candump's
    screen output has no times: the EMCY before the fault read still goes with it."""
    log, _ = _drive_run(tmp_path)
    screen = tmp_path / "screen.txt"
    lines = []
    for line in open(log).read().splitlines():
        _, chan, frame = line.split()
        cob, data = frame.split("#")
        raw = bytes.fromhex(data)
        lines.append(f"  {chan}  {cob}   [{len(raw)}]  {' '.join(f'{b:02X}' for b in raw)}")
    screen.write_text("\n".join(lines) + "\n")
    f = cananalyze.load(screen).findings
    assert (f.rule == "timestamps").any()  # read as a log without times
    (msg,) = f[f.rule == "drive_fault"].message
    assert msg.startswith("drive entered fault (statusword 0x") and "with EMCY 0x2310" in msg
