"""`cananalyze od`: each node's objects as its SDO transfers showed them, and the DCFs.

The traffic is python-canopen's: its SDO client configures a LocalNode serving a real
CiA 402 slave's EDS (ros2_canopen's), the node reboots, and the client writes again.
What `od` says is compared with what python-canopen's server holds (`get_data`), and the
DCFs are read back with canopen's `import_od`, configparser and cananalyze's `--eds`.
"""

from __future__ import annotations

import configparser
import json
import logging
import subprocess
import sys

import can
import canopen
import pyarrow.parquet as pq
import pytest

import cananalyze
from cananalyze.devices.profile import load_eds
from tests.conftest import REAL, ROOT, SAMPLES, real_file
from tests.helpers.virtual_bus import drain, patient_client, unique_channel

SLAVE_EDS = "ros-industrial__ros2_canopen/cia402_slave.eds"
NODE = 5


def _od_run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", "od", *args], capture_output=True, text=True
    )


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """candump of: boot-up; identity and name reads; heartbeat, TPDO1 and mode writes
    (mode twice); a reset (boot-up); the heartbeat written again and read back. Also the
    server's final object values."""
    logging.getLogger("canopen").setLevel(logging.ERROR)
    channel = unique_channel("od")
    recorder = can.Bus(interface="virtual", channel=channel)
    server_net, client_net = canopen.Network(), canopen.Network()
    server_net.connect(interface="virtual", channel=channel)
    client_net.connect(interface="virtual", channel=channel)
    try:
        drive = canopen.LocalNode(NODE, str(real_file(SLAVE_EDS)))
        server_net.add_node(drive)
        master = patient_client(NODE)
        client_net.add_node(master)
        drive.nmt.send_command(0x81)  # reset node: the boot-up message
        drive.nmt.send_command(0x80)  # pre-operational: its heartbeats say 0x7F, not 0
        master.sdo.upload(0x1000, 0)
        master.sdo.upload(0x1018, 1)
        assert master.sdo.upload(0x1008, 0) == b"iPOS"  # segmented
        master.sdo.download(0x1017, 0, (100).to_bytes(2, "little"))
        master.sdo.download(0x1800, 1, (0x80000185).to_bytes(4, "little"))
        master.sdo.download(0x1A00, 0, b"\x00")
        master.sdo.download(0x1A00, 1, (0x60410010).to_bytes(4, "little"))
        master.sdo.download(0x1A00, 0, b"\x01")
        master.sdo.download(0x1800, 1, (0x185).to_bytes(4, "little"))
        master.sdo.download(0x6060, 0, b"\x01")
        master.sdo.download(0x6060, 0, b"\x03")
        drive.nmt.send_command(0x81)  # the node reboots: a second life
        drive.nmt.send_command(0x80)
        master.sdo.download(0x1017, 0, (250).to_bytes(2, "little"))
        assert master.sdo.upload(0x1017, 0) == (250).to_bytes(2, "little")
        frames = drain(recorder)
        seen = [(0x1000, 0), (0x1018, 1), (0x1008, 0), (0x1017, 0), (0x1800, 1), (0x1A00, 0)]
        seen += [(0x1A00, 1), (0x6060, 0)]
        held = {k: drive.get_data(*k) for k in seen}
    finally:
        server_net.disconnect()
        client_net.disconnect()
        recorder.shutdown()
    path = tmp_path_factory.mktemp("od") / "configure.log"
    with can.CanutilsLogWriter(str(path), channel="vcan0") as w:  # python-can writes it
        for m in frames:
            w.on_message_received(m)
    return str(path), held


def test_od_rows_are_what_the_server_holds(recorded):
    log, held = recorded
    run = _od_run(log, "--format", "jsonl")
    assert run.returncode == 0, run.stderr
    rows = [json.loads(x) for x in run.stdout.splitlines()]
    assert {r["node"] for r in rows} == {NODE}
    by = {(r["life"], r["index"], r["subindex"]): r for r in rows}
    # every object of the first life: the bytes the server held at the end, but the
    # heartbeat time, written again (250) in the second life
    first = {(i, s): r for (life, i, s), r in by.items() if life == 1}
    assert set(first) == set(held)
    for k, r in first.items():
        want = (100).to_bytes(2, "little") if k == (0x1017, 0) else held[k]
        assert bytes.fromhex(r["data"]) == want, k
    assert first[(0x1008, 0)]["value"] == "iPOS" and first[(0x1008, 0)]["set_by"] == "read"
    mode = first[(0x6060, 0)]
    assert (mode["set_by"], mode["transfers"], mode["changes"]) == ("write", 2, 1)
    assert mode["history"] == "1 -> 3" and mode["value"] == "3"
    cob = first[(0x1800, 1)]
    assert cob["history"] == f"{0x80000185} -> {0x185}" and "valid" in cob["words"]
    assert first[(0x1A00, 1)]["words"].startswith("6041:00, 16 bit")
    # the second life: the heartbeat written, then read back
    second = {(i, s): r for (life, i, s), r in by.items() if life == 2}
    assert set(second) == {(0x1017, 0)}
    hb = second[(0x1017, 0)]
    assert (hb["value"], hb["transfers"], hb["set_by"]) == ("250", 2, "read")
    assert bytes.fromhex(hb["data"]) == held[(0x1017, 0)]
    assert all(r["t_first"] <= r["t"] for r in rows)


def test_text_names_each_life_and_change(recorded):
    log, _ = recorded
    run = _od_run(log)
    assert run.returncode == 0, run.stderr
    out = run.stdout
    assert out.startswith(f"node {NODE} (cia402), since boot-up 1 at ")
    assert f"node {NODE} (cia402), since boot-up 2 at " in out
    line = next(x for x in out.splitlines() if x.startswith("  0x6060:00"))
    assert "= 3 " in line and "written at" in line and "changed 1x: 1 -> 3" in line


def test_dcf_reads_back_in_canopen_and_as_eds(recorded, tmp_path):
    """With the node's EDS given, its DCF is that EDS with the log's values."""
    log, held = recorded
    eds = str(real_file(SLAVE_EDS))
    run = _od_run(log, "--eds", f"{NODE}={eds}", "--dcf", str(tmp_path / "dcf"), "-q")
    assert run.returncode == 0, run.stderr
    dcf = tmp_path / "dcf" / f"node{NODE}.dcf"
    assert dcf.is_file()
    od = canopen.import_od(str(dcf))
    assert od.node_id == NODE
    # the last life shows only the heartbeat time: its ParameterValue is the log's
    assert od[0x1017].value == 250
    ini = configparser.RawConfigParser()
    ini.optionxform = str
    ini.read(dcf)
    given = {s for s in ini.sections() if ini.has_option(s, "ParameterValue")}
    assert given == {"1017"}  # nothing the last life did not show
    assert ini.get("DeviceComissioning", "NodeID") == str(NODE)
    assert ini.get("1017", "DefaultValue")  # the EDS's default kept beside it
    assert ini.get("1017", "ParameterName") == "Producer Heartbeat Time"  # the EDS's
    assert od[0x2092][1].name == "UserVar1"  # the device's dictionary, not only what was seen
    assert load_eds(dcf).value(0x1017, 0) == 250
    assert load_eds(dcf).key == f"node{NODE}"


def test_dcf_of_a_node_known_by_its_profile_only(recorded, tmp_path):
    """Identified as CiA 402 from its 0x1000 read: objects the built-in profile lacks are
    added with a type of their size, and every value of the last life reads back."""
    log, held = recorded
    run = _od_run(log, "--dcf", str(tmp_path), "-q")
    assert run.returncode == 0, run.stderr
    od = canopen.import_od(str(tmp_path / f"node{NODE}.dcf"))
    assert od[0x1017].encode_raw(od[0x1017].value) == held[(0x1017, 0)]
    assert od[0x6041].name == "Statusword"  # from the CiA 402 profile


def test_export_and_load_give_the_same_rows(recorded, tmp_path):
    log, _ = recorded
    out = tmp_path / "tables"
    subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", log, "--parquet", str(out), "-q"],
        check=True,
    )
    table = pq.read_table(out / "od.parquet").to_pylist()  # pyarrow reads the file
    lines = _od_run(log, "--format", "jsonl").stdout.splitlines()
    assert table == [json.loads(x) for x in lines]
    frame = cananalyze.load(log).od
    assert frame.astype(object).where(frame.notna(), None).to_dict("records") == table


def test_a_log_without_sdo(tmp_path):
    log = tmp_path / "quiet.log"
    log.write_text("(0.000000) vcan0 705#05\n(0.100000) vcan0 705#05\n")
    run = _od_run(str(log), "--dcf", str(tmp_path / "d"))
    assert run.returncode == 0 and "no successful SDO transfer" in run.stdout
    assert not (tmp_path / "d").exists() or not list((tmp_path / "d").iterdir())


def test_names_from_the_log_are_shown_not_obeyed(tmp_path):
    """A segmented upload of text with a terminal escape in it: printed as \\x1b."""
    log = tmp_path / "esc.log"
    text = b"\x1b]0;pw\x07"  # 7 bytes: one segment
    lines = [
        "(0.000000) vcan0 605#4008100000000000",
        f"(0.001000) vcan0 585#41081000{len(text):02X}000000",
        "(0.002000) vcan0 605#6000000000000000",
        f"(0.003000) vcan0 585#{(0x00 | ((7 - 7) << 1)) | 0x01:02X}{text[:7].hex()}",
    ]
    log.write_text("\n".join(lines) + "\n")
    run = _od_run(str(log))
    assert run.returncode == 0, run.stderr
    assert "\x1b" not in run.stdout and "\\x1b]0;pw\\x07" in run.stdout


def _real_logs_with_sdo():
    if not REAL.is_dir():
        return []
    out = []
    for p in sorted(REAL.rglob("*")):
        if (
            p.suffix.lower() in {".log", ".asc", ".trc", ".blf", ".txt", ".csv", ".gz"}
            and p.is_file()
        ):
            out.append(p)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("path", _real_logs_with_sdo(), ids=lambda p: p.name)
def test_real_logs_dcfs_round_trip(path, tmp_path):
    """Every real log with SDO traffic: each node's DCF, read by canopen, holds the bytes
    the log's last life showed for every object it shows."""
    try:
        cap = cananalyze.load(str(path))
    except cananalyze.CananalyzeError:
        pytest.skip("not a log cananalyze reads")
    frame = cap.od
    rows = frame.astype(object).where(frame.notna(), None).to_dict("records")  # PDO: no data
    if not rows:
        pytest.skip("no successful SDO transfer")
    sdo_rows = [r for r in rows if r["set_by"] != "pdo"]  # PDO values: in no DCF
    run = _od_run(str(path), "--dcf", str(tmp_path), "-q", "--format", "jsonl")
    assert run.returncode == 0, run.stderr
    shown = [json.loads(x) for x in run.stdout.splitlines()]
    cols = ("node", "index", "subindex", "life", "data", "value", "set_by", "transfers")
    assert [tuple(r[c] for c in cols) for r in shown] == [tuple(r[c] for c in cols) for r in rows]
    last = {}
    for r in sdo_rows:
        k = (r.get("bus"), r["node"])
        last[k] = max(last.get(k, 0), r["life"])
    for (bus, node), life in last.items():
        name = f"node{node}.dcf" if bus is None else f"{bus}-node{node}.dcf"
        od = canopen.import_od(str(tmp_path / name))
        for r in sdo_rows:
            if (r.get("bus"), r["node"], r["life"]) != (bus, node, life):
                continue
            obj = od[r["index"]]
            var = obj[r["subindex"]] if hasattr(obj, "subindices") else obj
            assert var.encode_raw(var.value) == bytes.fromhex(r["data"]), (r["index"], r)


def _polled_log(path) -> None:
    """Node 5's position (0x6064) read 600 times, its value changing every 12th read; a
    boot-up after the 300th; a write of 0x6060 in each life; node 6's name read twice."""
    lines, t = [], 0.0
    value = 0
    for k in range(600):
        if k == 300:
            lines.append(f"({t:.6f}) vcan0 705#00")
            t += 0.001
        if k % 12 == 0:
            value += 7
        if k % 150 == 0:
            lines.append(f"({t:.6f}) vcan0 605#2F606000{k // 150:02X}000000")
            lines.append(f"({t + 0.0005:.6f}) vcan0 585#6060600000000000")
            t += 0.001
        lines.append(f"({t:.6f}) vcan0 605#4064600000000000")
        lines.append(f"({t + 0.0005:.6f}) vcan0 585#43646000{value.to_bytes(4, 'little').hex()}")
        t += 0.001
    for _ in range(2):
        lines.append(f"({t:.6f}) vcan0 606#4008100000000000")
        lines.append(f"({t + 0.0005:.6f}) vcan0 586#4F08100041000000")
        t += 0.001
    path.write_text("\n".join(lines) + "\n")


def _reference(cap) -> dict:
    """What the od rows must say, from load()'s sdo and events tables with pandas: per
    node, life (boot-ups before), object: transfers, changes of the bytes, the last."""
    boots = cap.events[cap.events["kind"] == "bootup"]
    sdo = cap.sdo[cap.sdo["result"] == "ok"].copy()
    sdo["life"] = [
        int(((boots["node"] == n) & (boots["t"] < t)).sum())
        for n, t in zip(sdo["node"], sdo["t"], strict=True)
    ]
    out = {}
    for key, g in sdo.groupby(["node", "life", "index", "subindex"], sort=True):
        data = g["data"].tolist()
        changes = sum(a != b for a, b in zip(data, data[1:], strict=False))
        out[tuple(int(x) for x in key)] = (len(g), changes, data[-1], float(g["t"].iloc[-1]))
    return out


@pytest.mark.parametrize("size", [None, 97, 1000])
@pytest.mark.parametrize("pure", [False, True], ids=["fast", "tracker"])
def test_polled_objects_counted_across_batches_and_paths(tmp_path, monkeypatch, size, pure):
    """Export's od table, cut in batches of `size` frames, on the fast path and the
    tracker's: the transfers, changes and last bytes that pandas finds in load()'s sdo
    table; the history keeps the first values and the last."""
    from tests.exported import export

    if pure:
        monkeypatch.setenv("CANANALYZE_PURE", "1")
    log = tmp_path / "polled.log"
    _polled_log(log)
    want = _reference(cananalyze.load(log))
    assert want[(5, 1, 0x6064, 0)][:2] == want[(5, 0, 0x6064, 0)][:2] == (300, 24)
    out = export(log, tmp_path / "x", size=size)["parquet"]
    rows = pq.read_table(out / "od.parquet").to_pylist()
    got = {
        (r["node"], r["life"], r["index"], r["subindex"]): (
            r["transfers"],
            r["changes"],
            r["data"],
            r["t"],
        )
        for r in rows
    }
    assert got == want
    pos = next(r for r in rows if (r["node"], r["life"], r["index"]) == (5, 0, 0x6064))
    shown = pos["history"].split(" -> ")
    # no profile types 0x6064 here: the values are shown as their bytes
    assert shown[:3] == [f"0x{(7 * i).to_bytes(4, 'little').hex()}" for i in (1, 2, 3)]
    assert shown[-2:] == ["...", f"0x{pos['data']}"] and pos["value"] is None
    assert len(shown) == 17  # the first 15, "...", the last


def test_pdo_mapped_objects_last_values(tmp_path):
    """commissioning.log remaps node 5's TPDO2 (0x285) by SDO to 0x6401:01 and 0x6401:03
    (0x1A01): the od rows of those two objects are the last 0x285 frame's two INT16s
    (python-can reads the log) in the DAT 7014's 0.1 degC, by PDO, the frames counted;
    0x6401:02, in no PDO, has no row. The DCF holds no PDO value (process data) and the
    export's table and load().od have the same rows."""
    log = str(SAMPLES / "commissioning.log")
    net = ("--network", str(SAMPLES / "network.toml"))
    run = _od_run(log, *net, "--format", "jsonl", "--dcf", str(tmp_path / "dcf"), "-q")
    assert run.returncode == 0, run.stderr
    rows = [json.loads(x) for x in run.stdout.splitlines()]
    mine = {(r["index"], r["subindex"]): r for r in rows if r["node"] == 5}
    frames = [m for m in can.CanutilsLogReader(log) if m.arbitration_id == 0x285]
    last = frames[-1]
    pdo = {k: r for k, r in mine.items() if r["set_by"] == "pdo"}
    assert set(pdo) == {(0x6401, 1), (0x6401, 3)}
    for sub, at in ((1, 0), (3, 2)):
        r = pdo[(0x6401, sub)]
        raw = int.from_bytes(last.data[at : at + 2], "little", signed=True)
        assert float(r["value"]) == pytest.approx(raw * 0.1)
        assert r["words"] == f"{r['value']} °C"
        assert r["t"] == pytest.approx(last.timestamp)
        assert r["t_first"] == pytest.approx(frames[0].timestamp)
        assert r["transfers"] == len(frames)
        assert r["data"] is None and r["name"] == f"ch{sub}"
        values = [int.from_bytes(m.data[at : at + 2], "little", signed=True) for m in frames]
        assert r["changes"] == sum(a != b for a, b in zip(values, values[1:], strict=False))
    text = _od_run(log, *net).stdout
    line = next(x for x in text.splitlines() if x.startswith("  0x6401:01") and "ch1" in x)
    assert "by PDO at" in line and f"{len(frames)} frames" in line
    od = canopen.import_od(str(tmp_path / "dcf" / "node5.dcf"))
    assert od[0x1017].value == 100  # an SDO write: configuration
    assert od[0x6401][1].value is None  # a PDO value: none
    out = tmp_path / "tables"
    subprocess.run(
        [sys.executable, "-m", "cananalyze", "export", log, *net, "--parquet", str(out), "-q"],
        check=True,
    )
    assert pq.read_table(out / "od.parquet").to_pylist() == rows
    frame = cananalyze.load(log, network=net[1]).od
    assert frame.astype(object).where(frame.notna(), None).to_dict("records") == rows


ROOT_EDS = ROOT / "decoders" / "dat7130.eds"


def _given_dcf(path) -> None:
    """The DAT 7130's EDS as a DCF: ParameterValues for 0x1017 (500 ms), 0x1800:05 (an
    event timer of 1000 ms) and 0x1016:01 (node 5 consumed at 100 ms)."""
    text = ROOT_EDS.read_text()
    for section, value in (("1017", "500"), ("1800sub5", "0x03E8"), ("1016sub1", "0x00050064")):
        at = text.index("PDOMapping=", text.index(f"[{section}]\n"))
        text = text[:at] + f"ParameterValue={value}\n" + text[at:]
    path.write_text(text)


def test_dcf_keeps_a_given_dcfs_values_of_objects_not_seen(tmp_path):
    """Node 6 described by a DCF; the log writes 0x1017 only. The DCF written: 0x1017 the
    log's, the given DCF's other ParameterValues kept (named in the comments as not
    seen), objects the given DCF set nothing for without one (DefaultValue applies)."""
    given = tmp_path / "given.dcf"
    _given_dcf(given)
    log = tmp_path / "hb.log"
    log.write_text(
        "(1000.000000) can0 706#00\n"
        "(1000.100000) can0 606#2B171000E8030000\n"
        "(1000.101000) can0 586#6017100000000000\n"
    )
    for desc in (given, ROOT_EDS):
        out = tmp_path / desc.suffix[1:]
        run = _od_run(str(log), "--eds", f"6={desc}", "--dcf", str(out), "-q")
        assert run.returncode == 0, run.stderr
        od = canopen.import_od(str(out / "node6.dcf"))
        assert od[0x1017].value == 1000  # the log's
        assert od[0x1800][3].value is None and od[0x1800][3].default == 0
        ini = configparser.RawConfigParser()
        ini.optionxform = str
        ini.read(out / "node6.dcf")
        valued = {s for s in ini.sections() if ini.has_option(s, "ParameterValue")}
        if desc == given:
            assert od[0x1800][5].value == 1000 and od[0x1016][1].value == 0x00050064
            assert valued == {"1017", "1800sub5", "1016sub1"}
            assert "Not seen in the log" in od.comments
            assert od.comments.splitlines()[3].split() == ["1016sub1", "1800sub5"]
        else:  # an EDS: nothing but the log's
            assert valued == {"1017"} and "Not seen" not in od.comments


def test_pdo_values_of_a_real_log_mapped_by_its_own_sdo_writes():
    """ZeroErr eRob node 11 (a real candump without times): the log maps TPDO1 (0x18B) to
    0x6041 (16 bit) and 0x6064 (32 bit) by SDO, and reads 0x6064 once before its 586 PDOs.
    The rows are the last 0x18B frame's values (its bytes read here from the text), the
    PDO's row replacing the earlier SDO read: the object's last value, on a log whose
    frames all have one time (ordered by frame)."""
    log = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    frames = []
    for line in log.read_text().splitlines():
        parts = line.split()
        if len(parts) >= 3 and parts[1] == "18B":
            frames.append(bytes.fromhex("".join(parts[3:])))
    run = _od_run(str(log), "--format", "jsonl")
    assert run.returncode == 0, run.stderr
    rows = {(r["index"], r["subindex"]): r for r in map(json.loads, run.stdout.splitlines())}
    status, position = rows[(0x6041, 0)], rows[(0x6064, 0)]
    assert status["set_by"] == position["set_by"] == "pdo"
    assert status["transfers"] == position["transfers"] == len(frames) == 586
    assert int(status["value"]) == int.from_bytes(frames[-1][0:2], "little")
    assert int(position["value"]) == int.from_bytes(frames[-1][2:6], "little")
    positions = [int.from_bytes(f[2:6], "little") for f in frames]
    assert position["changes"] == sum(
        a != b for a, b in zip(positions, positions[1:], strict=False)
    )
