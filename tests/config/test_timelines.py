"""load()'s tables and the exports (MCAP, rerun .rrd, Parquet, CSV) of the demo, read back.

Oracles: the demo log's text parsed independently here, the DAT 7014 TPDO2 values
the demo scripts (INTEGER16 in 0.1 degC), a real ros_canopen TMCM-1636 candump, and
the generator's known EMCY frames; the files are read with pandas, the `mcap` package
and rerun's RrdReader.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLES, real_file
from exported import (
    DEMO_DEVICES,
    assert_csv_tables,
    assert_mcap_is,
    assert_parquet_tables,
    assert_rrd_is,
    demo_capture,
    export,
    read_mcap,
    read_rrd,
)

import cananalyze
from cananalyze.cli.main import main
from cananalyze.core.frames import FLAG_RTR

DEMO = SAMPLES / "demo.log"


@pytest.fixture(scope="module")
def cap():
    return demo_capture(DEMO, bitrate=250000)  # the options `files` exports with


def _demo_lines() -> list[tuple[float, int, str]]:
    """(t, can_id, data hex) of each demo.log line, parsed with plain string ops."""
    out = []
    for line in DEMO.read_text().splitlines():
        ts, _chan, frame = line.split()[:3]
        cid, data = frame.split("#")
        out.append(
            (float(ts.strip("()")), int(cid, 16), "" if data.startswith("R") else data.lower())
        )
    return out


# --- Capture tables --------------------------------------------------------------


def test_frames_table_matches_log_text(cap):
    lines = _demo_lines()
    f = cap.frames
    assert len(f) == len(lines)
    assert f["t"].tolist() == [x[0] for x in lines]
    assert f["can_id"].tolist() == [x[1] for x in lines]
    assert f["data"].tolist() == [bytes.fromhex(x[2]) for x in lines]  # bytes
    assert cap.data_hex().tolist() == [x[2] for x in lines]  # and as the log's hex text
    data_rows = [i for i, x in enumerate(lines) if x[2]]
    assert f["dlc"][data_rows].tolist() == [len(lines[i][2]) // 2 for i in data_rows]
    # 0x000 NMT and 0x080 SYNC belong to no node; heartbeats 0x70N do
    nmt = f[f["can_id"] == 0]
    assert (nmt["service"] == "nmt").all() and nmt["node"].isna().all()
    hb = f[(f["can_id"] & 0x780) == 0x700]
    assert set(hb["service"].astype(str)) == {
        "heartbeat",
        "bootup",
        "guard_response",
        "guard_request",
    }
    assert (hb["node"].astype(int) == (hb["can_id"] & 0x7F)).all()
    tpdo = f[f["service"] == "tpdo"]
    assert sorted(tpdo["pdo"].dropna().unique().tolist()) == [1, 2]


def test_rtr_frames_have_empty_data(cap):
    rtr = (cap.batch.flags & FLAG_RTR) != 0
    assert rtr.any()
    assert (cap.frames["data"][rtr] == b"").all()
    assert (cap.data_hex()[rtr] == "").all()


def test_signals_long_and_wide_agree_with_manual_values(cap):
    s = cap.signals
    ch1 = s[(s["node"] == 5) & (s["pdo"] == "tpdo2") & (s["signal"] == "ch1")]
    assert len(ch1) == 20
    # first DAT 7014 TPDO2 in the demo: 285#D700DC00F1FFE803 = 215, 220, -15, 1000 x 0.1 degC
    first = s[(s["node"] == 5) & (s["t"] == ch1["t"].iloc[0])].set_index("signal")["value"]
    assert first.to_dict() == pytest.approx({"ch1": 21.5, "ch2": 22.0, "ch3": -1.5, "ch4": 100.0})
    assert set(ch1["unit"]) == {"°C"}
    # MCB 560 digital inputs have no unit: "" (documented), values float64 for plotting
    assert set(s[(s["node"] == 3) & (s["pdo"] == "tpdo1")]["unit"]) == {""}
    assert s["value"].dtype == np.float64
    wide = cap.signals_wide()
    col = wide["5/tpdo2/ch1"].dropna()
    assert col.index.tolist() == ch1["t"].tolist()
    assert col.tolist() == ch1["value"].tolist()
    assert wide.notna().sum().sum() == len(s)


def test_events_cover_boot_nmt_emcy_sdo_and_states(cap):
    e = cap.events
    assert (e["t"].diff().dropna() >= 0).all()
    kinds = e["kind"].astype(str).value_counts().to_dict()
    assert kinds["bootup"] == 3 and kinds["nmt"] == 1 and kinds["emcy"] == 2
    assert kinds["sdo"] == len(cap.sdo) == 7
    emcy = e[e["kind"] == "emcy"]
    assert emcy["level"].astype(str).tolist() == ["error", "info"]  # raised, then reset
    assert "0x8100" in emcy["message"].iloc[0]
    abort = e[(e["kind"] == "sdo") & (e["level"] == "warning")]
    assert len(abort) == 1 and "does not exist" in abort["message"].iloc[0]
    # DAT 7014 device type as its manual gives it, in hex as well (like the text output)
    assert "SDO upload 0x1000:00 Device type = 262545 (0x40191) ok" in e["message"].tolist()
    states = e[e["kind"] == "nmt_state"]
    # each node: bootup then operational; repeated heartbeats give no new event
    assert states.groupby("node").size().to_dict() == {3: 2, 5: 2, 10: 2}


def test_nodes_table(cap):
    n = cap.nodes
    assert n.index.tolist() == [3, 5, 10]
    f = cap.frames
    assert n["frames"].to_dict() == f["node"].value_counts().sort_index().to_dict()
    assert n.loc[5, "frames_heartbeat"] == 20 and n.loc[10, "frames_guard_response"] == 10
    assert set(n["last_state"]) == {"operational"}
    assert n.loc[5, "vendor_id"] == 0x3CD and n.loc[5, "device_name"] == "DAT7014"


def test_sdo_table_from_tracker(cap):
    sdo = cap.sdo
    assert sdo["result"].tolist().count("abort") == 1
    assert sdo.loc[sdo["result"] == "abort", "abort_code"].iloc[0] == 0x06020000


def test_real_tmcm_log_events_in_frame_order():
    c = cananalyze.load(real_file("nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt"))
    assert len(c.frames) == 115
    e = c.events
    # no timestamps: frame order decides (a boot story, judged at the end of the log, has
    # no frame row)
    assert e.loc[e["kind"] != "boot", "row"].is_monotonic_increasing
    assert e.loc[e["kind"] == "boot", "row"].isna().all()
    nmt = e[e["kind"] == "nmt"]["message"].tolist()
    assert nmt == ["NMT reset communication node 1", "NMT start node 1", "NMT stop node 1"]
    emcy = e[e["kind"] == "emcy"]
    assert "0x6320" in emcy["message"].iloc[0] and emcy["level"].astype(str).tolist() == [
        "error",
        "info",
    ]
    assert len(c.sdo) == 48 and (c.sdo["result"] == "ok").all()


def test_import_and_help_stay_light():
    code = (
        "import sys, cananalyze; from cananalyze.cli.main import build_parser; build_parser();"
        "print(sorted(m for m in ('pandas','rerun','mcap','pyarrow','can','canopen','numpy','yaml') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# --- MCAP ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The demo exported in every format, as `export` writes it (rules on)."""
    out = tmp_path_factory.mktemp("demo")
    return export(DEMO, out, ("parquet", "csv", "mcap", "rrd"), bitrate=250000, device=DEMO_DEVICES)


def test_mcap_round_trip(cap, files):
    m = assert_mcap_is(cap, files["mcap"])
    assert set(m.messages) == {
        "/node/3/tpdo1",
        "/node/3/tpdo2",
        "/node/5/tpdo2",
        "/node/3/nmt_state",
        "/node/5/nmt_state",
        "/node/10/nmt_state",
        "/canopen/events",
        "/can/frames",
    }
    assert len(m.messages["/can/frames"]) == len(_demo_lines())
    assert all(c.compression == "zstd" for c in m.summary.chunk_indexes)
    # schema: numbers as numbers, unit in the description
    assert m.schemas["/node/5/tpdo2"][2]["properties"]["ch1"] == {
        "type": "number",
        "description": "unit: °C",
    }
    # first DAT 7014 TPDO2 in the demo: 285#D700DC00F1FFE803 = 215, 220, -15, 1000 x 0.1 degC
    assert m.docs("/node/5/tpdo2")[0] == pytest.approx(
        {"ch1": 21.5, "ch2": 22.0, "ch3": -1.5, "ch4": 100.0}
    )
    assert all(type(v) is int for d in m.docs("/node/3/tpdo1") for v in d.values())
    logs = m.docs("/canopen/events")
    assert sorted({d["level"] for d in logs}) == [2, 3, 4]
    assert logs[0]["file"] == "demo.log" and logs[0]["line"] == 1
    times = [t for _, t, _ in m.in_time_order]
    assert times == sorted(times) and len(times) == m.summary.statistics.message_count
    assert [n["node"] for n in json.loads(m.attachments["nodes.json"])] == [3, 5, 10]


def test_mcap_failure_at_the_end_leaves_no_file(tmp_path, monkeypatch):
    """The metadata written last fails: the export stops and the file never appears."""
    from cananalyze.outputs.mcap import stream as mcap_stream

    def boom(*_a):
        raise RuntimeError("disk full")

    monkeypatch.setattr(mcap_stream, "write_metadata", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        export(DEMO, tmp_path, ("mcap",), device=DEMO_DEVICES)
    assert list(tmp_path.iterdir()) == []


# --- rerun -----------------------------------------------------------------------


def test_rrd_round_trip(cap, files):
    r = assert_rrd_is(cap, files["rrd"], bitrate=250000)
    signal_paths = {
        f"/node/{n}/{p}/{s}"
        for n, p, s in cap.signals[["node", "pdo", "signal"]]
        .drop_duplicates()
        .itertuples(index=False)
    }
    assert signal_paths | {
        "/node/3/nmt",
        "/node/5/nmt",
        "/node/10/nmt",
        "/events",
        "/bus/load",
    } == set(r.rows)
    assert [v for _, v in r.values("/node/5/tpdo2/ch1", "Scalars:scalars")][:1] == [21.5]
    assert [v for _, v in r.values("/node/5/nmt", "StateChange:state")] == [
        "pre-operational",  # after its boot-up (CiA 301)
        "operational",
    ]
    assert {row["TextLog:level"][0] for row in r.rows["/events"]} == {"INFO", "WARN", "ERROR"}
    load = [v for _, v in r.values("/bus/load", "Scalars:scalars")]
    assert all(0 <= x < 100 for x in load) and max(load) > 0


def _views(layout) -> list[tuple[str, str]]:
    """(kind of view or container, display name) of each part of an .rrd's layout."""
    out = []
    for row in layout:
        d = dict(row)
        name = d.get("ViewBlueprint:display_name") or d.get("ContainerBlueprint:display_name")
        kind = d.get("ViewBlueprint:class_identifier") or d.get("ContainerBlueprint:container_kind")
        if name:
            out.append((kind, name))
    return out


def test_blueprint_has_a_plot_per_pdo_and_a_lane_per_node(cap, files):
    """Checked against a screenshot of the viewer: a node's PDOs on one axis hid
    the digital input bytes under 10 V analogue values, and a `/node/*/nmt`
    pattern left the NMT lanes empty, so both are spelled out."""
    from cananalyze.outputs.rerun.send import Layout

    layout = Layout()
    layout.add(cap)
    bp = layout.blueprint()
    plots, states, log = bp.root_container.contents
    columns = {c.name: [(v.origin, v.name) for v in c.contents] for c in plots.contents[:-1]}
    assert columns == {
        "node 3": [
            ("/node/3/tpdo1", "node 3 TPDO1 (0x183)"),
            ("/node/3/tpdo2", "node 3 TPDO2 (0x283)"),
        ],
        "node 5": [("/node/5/tpdo2", "node 5 TPDO2 (0x285)")],
    }
    assert plots.contents[-1].origin == "/bus"
    assert list(states.contents) == ["+ /node/3/nmt", "+ /node/5/nmt", "+ /node/10/nmt"]
    assert log.origin == "/events"
    # the exported recording carries that layout as its default blueprint
    names = [name for _, name in _views(read_rrd(files["rrd"]).layout)]
    for name in ("node 3 TPDO1 (0x183)", "node 3 TPDO2 (0x283)", "node 5 TPDO2 (0x285)"):
        assert repr([name]) in names
    assert repr(["NMT states"]) in names and repr(["events"]) in names


def test_blueprint_puts_many_nodes_in_a_grid(tmp_path):
    """16 node columns side by side were a few pixels wide each in the viewer."""
    import rerun.blueprint as rrb

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from generate import generate

    from cananalyze.formats.logfile import write_log
    from cananalyze.outputs.rerun.send import Layout

    write_log(generate(3000), tmp_path / "g.log")
    c = cananalyze.load(tmp_path / "g.log", device=[f"{n}=dat7014" for n in range(1, 17)])
    layout = Layout()
    layout.add(c)
    bp = layout.blueprint()
    plots, states, _ = bp.root_container.contents
    assert isinstance(plots, rrb.Grid)
    assert [col.name for col in plots.contents[:-1]] == [f"node {n}" for n in range(1, 17)]
    assert len(states.contents) == 16


def test_bus_load_of_steady_traffic_is_flat_to_the_end():
    """A frame every 10 ms: every window, the log's short tail included, shows the
    same load (the tail once showed a spike: a few ms ending on a frame, scaled up)."""
    from cananalyze.protocol.busload import load_series

    t = 100.0 + np.arange(101) * 0.01  # the last frame opens a 0.1 s window on its own
    starts, load = load_series(t, np.full(t.size, 111), 0.1, 250000)
    assert starts[0] == t[0] and len(starts) == 10
    assert load == pytest.approx(np.full(10, 111 / 0.01 / 250000 * 100), rel=0.15)


def test_bus_load_windows_start_where_their_frames_are_when_times_go_back():
    """A frame logged 0.15 s before the first one (a log's times going back) opens the
    window 9.8 s, not one labelled 10.0 s that holds frames of 9.85 s."""
    from cananalyze.protocol.busload import load_series

    t = np.array([10.0, 10.05, 9.85, 10.28])
    starts, load = load_series(t, np.full(t.size, 100), 0.1)
    assert starts.tolist() == pytest.approx([9.8, 9.9, 10.0, 10.1, 10.2])
    assert load[starts.round(1).tolist().index(9.8)] == pytest.approx(100 / 0.1)


def test_decode_rerun_and_connect_are_exclusive(capsys):
    assert main(["decode", str(DEMO), "--rerun", "--connect", "127.0.0.1:9876"]) == 2
    assert "give one of them" in capsys.readouterr().err


# --- Parquet / CSV ---------------------------------------------------------------


def test_parquet_round_trip(cap, files):
    assert_parquet_tables(cap, files["parquet"])
    f = pd.read_parquet(files["parquet"] / "frames.parquet")
    assert f["t"].tolist() == [x[0] for x in _demo_lines()]
    # NMT, SYNC and TIME belong to no node: a nullable Int16 with those rows missing
    no_node = [cid in (0x000, 0x080, 0x100) for _, cid, _ in _demo_lines()]
    assert str(f["node"].dtype) == "Int16" and f["node"].isna().tolist() == no_node
    sdo = pd.read_parquet(files["parquet"] / "sdo.parquet")
    assert len(sdo) == 7 and sdo["result"].tolist().count("abort") == 1


def test_parquet_and_csv_with_mixed_findings_values(tmp_path):
    """Findings' measured/expected hold numbers and text (160.3 ms, "0xFFA8", "cleared"):
    Parquet needs one type per column, so they are written as text."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from generate import generate

    from cananalyze.formats.logfile import write_log

    write_log(generate(5000, faults=True), tmp_path / "g.log")  # the faulty bus: findings
    devices = {n: "dat7014" for n in range(1, 17)}
    c = cananalyze.load(tmp_path / "g.log", device=devices)
    kinds = {type(v) for v in c.findings["measured"] if v is not None}
    assert str in kinds and kinds & {int, float}  # the case that failed
    out = export(tmp_path / "g.log", tmp_path, ("parquet", "csv"), device=devices)
    back = pd.read_parquet(out["parquet"] / "findings.parquet")
    assert len(back) == len(c.findings)
    assert back["measured"].tolist() == [
        None if v is None else str(v) for v in c.findings["measured"]
    ]
    assert back["rule"].tolist() == c.findings["rule"].tolist()
    assert_parquet_tables(c, out["parquet"])
    assert_csv_tables(c, out["csv"])


def test_csv_tables(cap, files):
    assert_csv_tables(cap, files["csv"])
    f = pd.read_csv(files["csv"] / "frames.csv", keep_default_na=False, dtype={"data": str})
    assert f["data"].tolist() == [x[2] for x in _demo_lines()]
    s = pd.read_csv(files["csv"] / "signals.csv")
    assert s["value"].tolist() == pytest.approx(cap.signals["value"].tolist())


# --- CLI -------------------------------------------------------------------------


def test_cli_export_all_outputs(tmp_path, capsys):
    """Every format from one run of `export` with the rules on (the default): each file holds
    load()'s log, and the findings are those `check --json` reports."""
    rc = main(
        [
            "export",
            str(DEMO),
            "--mcap",
            str(tmp_path / "a.mcap"),
            "--rrd",
            str(tmp_path / "a.rrd"),
            "--parquet",
            str(tmp_path / "pq"),
            "--csv",
            str(tmp_path / "csv"),
        ]
    )
    assert rc == 0
    err = capsys.readouterr().err
    assert "exported 185 frames" in err and "\x1b" not in err  # no progress bar off a terminal
    c = cananalyze.load(DEMO)
    m = assert_mcap_is(c, tmp_path / "a.mcap")
    assert len(m.messages["/can/frames"]) == 185
    assert len(assert_rrd_is(c, tmp_path / "a.rrd").rows["/events"]) == len(c.events)
    assert_parquet_tables(c, tmp_path / "pq")
    assert_csv_tables(c, tmp_path / "csv")
    assert main(["check", str(DEMO), "--json", str(tmp_path / "f.json"), "-q"]) in (0, 1)
    capsys.readouterr()
    reported = json.loads((tmp_path / "f.json").read_text())
    findings = pd.read_parquet(tmp_path / "pq" / "findings.parquet")
    assert findings["rule"].tolist() == [f["rule"] for f in reported]
    assert findings["message"].tolist() == [f["message"] for f in reported]
    assert findings["t"].tolist() == [f["t"] for f in reported]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["export", str(DEMO)], "give at least one of"),
        (["export", str(DEMO), "--mcap", "/nonexistent/dir/x.mcap"], "does not exist"),
        (["export", "missing.log", "--mcap", "x.mcap"], "missing.log: no such file"),
        (["export", str(DEMO), "--parquet", "/dev/null/pq"], "cannot create the output"),
    ],
)
def test_cli_export_errors_are_one_line(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "x.mcap").exists()


def test_cli_export_disk_full_on_the_writer_thread_is_one_line(capsys, tmp_path, monkeypatch):
    """An OSError raised where the streamed tables are written reaches the user as one line."""
    from cananalyze.outputs.tables import writer as table_sink

    def full(self, table):
        raise OSError(28, "No space left on device", str(self.path))

    monkeypatch.setattr(table_sink.Sink, "_write", full)
    assert main(["export", str(DEMO), "--parquet", str(tmp_path / "pq"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "pq" in err[0], err
    assert not list((tmp_path / "pq").glob("*.parquet"))  # nothing half-written is left


def test_decode_with_mcap_writes_text_and_timeline(tmp_path, capsys):
    rc = main(["decode", str(DEMO), "--mcap", str(tmp_path / "d.mcap")])
    assert rc == 0
    assert "NMT start all nodes" in capsys.readouterr().out
    m = read_mcap(tmp_path / "d.mcap")
    events = m.messages["/canopen/events"]
    assert len(events) == 22  # 19, and the boot story of each of the 3 nodes
    assert sum(b"boot-up 1: operational" in e[2] for e in events) == 3


def test_export_of_generated_log(tmp_path):
    """A generated log's frames, events and EMCY (the generator's known frames) in every file."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from generate import generate

    from cananalyze.formats.logfile import write_log

    batch = generate(20000)
    log = tmp_path / "g.log"
    write_log(batch, log)
    c = cananalyze.load(log)
    assert len(c) == 20000
    out = export(log, tmp_path, ("mcap", "rrd"))
    m = assert_mcap_is(c, out["mcap"])
    assert len(m.messages["/can/frames"]) == 20000
    emcy = int(((batch.can_id & 0x780) == 0x080).sum() - (batch.can_id == 0x080).sum())
    assert (c.events["kind"] == "emcy").sum() == emcy
    assert sum(" EMCY " in d["message"] for d in m.docs("/canopen/events")) >= emcy
    r = assert_rrd_is(c, out["rrd"])
    assert len(r.rows["/events"]) == len(c.events)
