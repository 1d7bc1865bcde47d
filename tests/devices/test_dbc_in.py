"""`--dbc FILE`: frames decoded by a DBC (cantools' layout, our columns), checked against
cantools' own `decode_message` on the same frames (the independent reader)."""

from __future__ import annotations

import json
import subprocess
import sys

import cantools
import numpy as np
import pytest

import cananalyze
from cananalyze.core.frames import FLAG_EXT, FrameBatch
from cananalyze.pipeline import Options, build_decoder, run
from tests.conftest import real_file

AXIO = "calumroy__CANopen_socketCAN_Test/"

# a mixed bus: a Motorola signal, signed Intel, a value table, an extended identifier,
# a multiplexed message and a float; identifiers CANopen does not use (0x10A) and one
# that is a PDO (0x1A5 = TPDO1 of node 0x25)
MIXED_DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 266 Engine: 8 ECU
 SG_ rpm : 7|16@0+ (0.25,0) [0|16383.75] "rpm" ECU
 SG_ temp : 16|8@1- (1,-40) [-168|87] "degC" ECU
 SG_ gear : 24|3@1+ (1,0) [0|7] "" ECU
 SG_ torque : 39|12@0- (0.5,0) [-1024|1023.5] "Nm" ECU

BO_ 2566844926 Ext: 8 ECU
 SG_ pressure : 0|32@1+ (0.01,0) [0|42949672.95] "kPa" ECU
 SG_ level : 32|32@1- (1,0) [0|0] "" ECU

BO_ 421 Drive: 8 ECU
 SG_ status : 0|16@1+ (1,0) [0|65535] "" ECU
 SG_ speed : 16|32@1- (0.001,0) [0|0] "m/s" ECU

BO_ 300 Mux: 8 ECU
 SG_ sel M : 0|8@1+ (1,0) [0|255] "" ECU
 SG_ a m0 : 8|16@1+ (1,0) [0|65535] "" ECU
 SG_ b m1 : 8|16@1- (0.1,0) [0|0] "V" ECU

BO_ 301 Flt: 8 ECU
 SG_ x : 0|32@1- (1,0) [0|0] "" ECU
 SG_ y : 32|32@1+ (1,0) [0|0] "" ECU

VAL_ 266 gear 0 "park" 1 "reverse" 2 "neutral" 3 "drive" ;
SIG_VALTYPE_ 301 x : 1;
"""


def _batch(rows: list[tuple[int, bytes, bool]], t0: float = 100.0) -> FrameBatch:
    fb = FrameBatch.allocate(len(rows), ("can0",))
    for i, (ident, data, ext) in enumerate(rows):
        fb.t[i] = t0 + i * 0.001
        fb.can_id[i] = ident
        fb.flags[i] = FLAG_EXT if ext else 0
        fb.dlc[i] = len(data)
        fb.data[i, : len(data)] = np.frombuffer(data, np.uint8)
        fb.line[i] = i + 1
    return fb


def _decoded(fb: FrameBatch, dbc) -> tuple:
    opts = Options(dbc=dbc)
    decoder = build_decoder(opts)
    return decoder.decode(fb), decoder


def _values(batch, cob_id: int) -> dict[str, list]:
    out: dict[str, list] = {}
    for sb in batch.signals:
        if sb.cob_id == cob_id:
            for k, v in sb.columns.items():
                out.setdefault(k, []).extend(v.tolist())
    return out


def _same(got: list, want: list, name: str) -> None:
    g = np.array(got, np.float64)
    w = np.array(want, np.float64)
    both_nan = np.isnan(g) & np.isnan(w)
    assert np.allclose(g[~both_nan], w[~both_nan], rtol=1e-12, atol=1e-9), name
    assert (np.isnan(g) == np.isnan(w)).all(), name


def test_real_axiomatic_log_decodes_by_its_authors_dbc():
    log = real_file(AXIO + "can_log_070825_brake_sensor_test1.log")
    dbc = real_file(AXIO + "axiomatic_23123-1.dbc")
    cap = cananalyze.load(log, dbc=dbc)
    sig = cap.signals
    first = sig[sig.signal == "input1_value"].iloc[0]
    assert first.value == pytest.approx(3.128)  # raw 0x0C38 = 3128, scale 0.001
    assert first.node == 127 and first.pdo == "tpdo1"
    db = cantools.database.load_file(str(dbc))
    frames = cap.frames
    checked = 0
    for cob in (0x1FF, 0x2FF, 0x3FF):
        msg = db.get_message_by_frame_id(cob)
        sel = frames[frames.can_id == cob]
        assert len(sel) > 1000
        want = [msg.decode(d, decode_choices=False) for d in sel.data]
        for s in msg.signals:
            got = sig[(sig.cob_id == cob) & (sig.signal == s.name)].value.tolist()
            _same(got, [w[s.name] for w in want], s.name)
            checked += len(got)
    assert checked > 16000 * 4 * 0.9
    # the DBC's unit reaches the table
    assert set(sig[sig.signal == "input11_freq"].unit) == {"Hz"}


def test_mixed_bus_matches_cantools(tmp_path):
    path = tmp_path / "mixed.dbc"
    path.write_text(MIXED_DBC)
    db = cantools.database.load_file(str(path))
    rng = np.random.default_rng(21)
    rows = []
    for _ in range(400):
        for ident, ext in (
            (0x10A, False),
            (0x18FEF1FE, True),
            (0x1A5, False),
            (300, False),
            (301, False),
        ):
            data = rng.integers(0, 256, 8, dtype=np.uint8).tobytes()
            if ident == 300:
                data = bytes([int(rng.integers(0, 3))]) + data[1:]
            if ident == 301:  # a finite float in x
                data = np.float32(rng.normal() * 100).tobytes() + data[4:]
            rows.append((ident, data, ext))
    batch, _ = _decoded(_batch(rows), (path,))
    for msg in db.messages:
        want = []
        for ident, data, _ in rows:
            if ident == msg.frame_id:
                try:
                    w = msg.decode(data, decode_choices=False)
                except cantools.database.DecodeError:  # a multiplexer value the DBC lacks
                    w = {"sel": data[0]}  # ours: the multiplexer, the others NaN
                want.append({s.name: w.get(s.name, np.nan) for s in msg.signals})
        got = _values(batch, msg.frame_id)
        assert set(got) == {s.name for s in msg.signals}, msg.name
        for s in msg.signals:
            _same(got[s.name], [w[s.name] for w in want], f"{msg.name}.{s.name}")
    # the non-CANopen identifier is its message; the PDO keeps its name
    by_cob = {sb.cob_id: sb for sb in batch.signals}
    assert by_cob[0x10A].pdo == "Engine" and by_cob[0x10A].node == -1
    assert by_cob[0x1A5].pdo == "tpdo1" and by_cob[0x1A5].node == 0x25
    assert by_cob[0x10A].units["rpm"] == "rpm"
    assert by_cob[0x10A].choices["gear"][3] == "drive"


def test_value_tables_and_messages_in_text_and_jsonl(tmp_path):
    path = tmp_path / "mixed.dbc"
    path.write_text(MIXED_DBC)
    rows = [(0x10A, bytes([0x10, 0x00, 0x28, 0x03, 0x00, 0x10, 0, 0]), False)]
    log = tmp_path / "bus.log"
    log.write_text("".join(f"(1.0) can0 {i:03X}#{d.hex().upper()}\n" for i, d, _ in rows))
    cmd = [sys.executable, "-m", "cananalyze", "decode", str(log), "--dbc", str(path)]
    text = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout
    assert "Engine  rpm=1024 rpm temp=0 degC gear=3 (drive) torque=0.5 Nm" in text
    out = subprocess.run([*cmd, "--format", "jsonl"], capture_output=True, text=True, check=True)
    rec = json.loads(out.stdout.splitlines()[0])
    assert rec["message"] == "Engine"
    assert rec["signals"]["gear"] == 3 and rec["labels"] == {"gear": "drive"}
    assert rec["units"]["temp"] == "degC"


def test_short_frame_is_a_note_not_a_value(tmp_path):
    path = tmp_path / "mixed.dbc"
    path.write_text(MIXED_DBC)
    batch, _ = _decoded(_batch([(0x10A, b"\x01\x02", False), (0x10A, bytes(8), False)]), (path,))
    assert [sb.rows.tolist() for sb in batch.signals] == [[1]]
    notes = [n["pdo_problem"] for _, n in batch.row_notes]
    assert any("shorter than the 6 bytes of DBC message Engine" in n for n in notes)


def test_dbc_identifiers_are_not_unknown(tmp_path):
    path = tmp_path / "mixed.dbc"
    path.write_text(MIXED_DBC)
    log = tmp_path / "bus.log"
    log.write_text("".join(f"({i}.0) can0 10A#0000000000000000\n" for i in range(20)))
    without = [f.rule for f in cananalyze.check(log)]
    with_dbc = [f.rule for f in cananalyze.check(log, dbc=(path,))]
    assert "unknown_cob_id" in without
    assert "unknown_cob_id" not in with_dbc


@pytest.mark.parametrize(
    "content, reason",
    [
        ('BO_ 1 X: 8 Y\n SG_ a : 0|16@1+ (1,0) [0|0] "" Y\n garbage here\n', "Invalid syntax"),
        (None, "no such DBC file"),
    ],
)
def test_bad_dbc_is_one_line(tmp_path, content, reason):
    path = tmp_path / "bad.dbc"
    if content is not None:
        path.write_text(content)
    log = tmp_path / "bus.log"
    log.write_text("(1.0) can0 10A#00\n")
    for cmd in (
        ["decode", str(log), "--dbc"],
        ["export", str(log), "--csv", str(tmp_path / "c"), "--dbc-in"],
    ):
        r = subprocess.run(
            [sys.executable, "-m", "cananalyze", *cmd, str(path)], capture_output=True, text=True
        )
        assert r.returncode == 2
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0] and reason in lines[0], r.stderr
        assert "Traceback" not in r.stderr


def test_export_tables_carry_dbc_signals(tmp_path):
    import pyarrow.parquet as pq

    path = tmp_path / "mixed.dbc"
    path.write_text(MIXED_DBC)
    log = tmp_path / "bus.log"
    log.write_text(
        "".join(
            f"({i}.0) can0 10A#0100{i:02X}0300100000\n({i}.5) can0 1A5#0100E8030000\n"
            for i in range(5)
        )
    )
    out = tmp_path / "pq"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "cananalyze",
            "export",
            str(log),
            "--dbc-in",
            str(path),
            "--parquet",
            str(out),
        ],
        check=True,
        capture_output=True,
    )
    # one row per frame, a column per signal (the DBC's message in `pdo`)
    t = pq.read_table(out / "signals.parquet").to_pandas()
    temp = t[t.pdo == "Engine"]
    assert temp["temp"].tolist() == [-40.0, -39.0, -38.0, -37.0, -36.0]
    assert temp["speed"].isna().all()
    speed = t[t["speed"].notna()]
    assert speed["speed"].tolist() == pytest.approx([1.0] * 5)
    assert set(speed.node) == {0x25}


def test_mcap_and_rerun_carry_dbc_messages(tmp_path):
    from tests.exported import read_mcap, read_rrd

    path = tmp_path / "mixed.dbc"
    path.write_text(MIXED_DBC)
    log = tmp_path / "bus.log"
    log.write_text(
        "".join(
            f"({i}.0) can0 10A#{(i * 4):04X}{i:02X}0300100000\n({i}.5) can0 1A5#0100E8030000\n"
            for i in range(6)
        )
    )
    mcap, rrd = tmp_path / "x.mcap", tmp_path / "x.rrd"
    cmd = ["export", str(log), "--dbc-in", str(path), "--mcap", str(mcap), "--rrd", str(rrd)]
    subprocess.run([sys.executable, "-m", "cananalyze", *cmd, "-q"], check=True)
    m = read_mcap(mcap)
    docs = m.docs("/dbc/Engine")  # a message on no node's identifier
    assert [d["rpm"] for d in docs] == [i * 4 * 0.25 for i in range(6)]  # big-endian 0x00XX
    assert [d["temp"] for d in docs] == [i - 40 for i in range(6)]
    assert len(m.docs("/node/37/tpdo1")) == 6  # the PDO the DBC describes keeps its topic
    r = read_rrd(rrd)
    assert len(r.rows["/dbc/Engine/rpm"]) == 6
    assert len(r.rows["/node/37/tpdo1/speed"]) == 6


def test_live_bus_decodes_by_the_dbc(tmp_path):
    """`live --dbc`: the option reaches Options, and frames from python-can's virtual bus
    decode by the DBC as they do offline."""
    import io
    import threading
    import time

    import can

    from cananalyze.cli.common import options
    from cananalyze.cli.main import build_parser
    from cananalyze.formats.live import LiveSource
    from cananalyze.outputs.text.writer import TextWriter

    path = tmp_path / "mixed.dbc"
    path.write_text(MIXED_DBC)
    args = build_parser().parse_args(["live", "-i", "virtual", "-c", "x", "--dbc", str(path)])
    opts = options(args)
    assert opts.dbc == (str(path),)
    channel = f"dbc-live-{time.monotonic_ns()}"
    rx = can.Bus(interface="virtual", channel=channel)
    source = LiveSource(rx, interval=0.01, batch_max=4)

    def pump():
        tx = can.Bus(interface="virtual", channel=channel)
        try:
            for k in range(10):
                data = bytes([0x00, 4 * k, 40 + k, 3, 0, 0x10, 0, 0])
                tx.send(can.Message(arbitration_id=0x10A, data=data, is_extended_id=False))
                time.sleep(0.002)
            time.sleep(0.2)
        finally:
            tx.shutdown()
            source.stop()

    th = threading.Thread(target=pump)
    th.start()
    out = io.StringIO()
    run(source, build_decoder(opts), [TextWriter(out)], opts)
    th.join()
    lines = out.getvalue().splitlines()
    assert len(lines) == 10
    for k, line in enumerate(lines):
        assert f"Engine  rpm={k:g} rpm temp={k} degC gear=3 (drive)" in line, line
