"""Capture tables and the timeline exporters (MCAP, rerun .rrd, Parquet, CSV), read back.

Oracles: the demo log's text parsed independently here, the DAT 7014 TPDO2 values
the demo scripts (INTEGER16 in 0.1 degC), and a real ros_canopen TMCM-1636 candump.
"""

from __future__ import annotations

import json
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SAMPLES, real_file
from timeline_helpers import demo_capture

import cananalyze
from cananalyze.cli.main import main
from cananalyze.frames import FLAG_RTR

DEMO = SAMPLES / "demo.log"


@pytest.fixture(scope="module")
def cap():
    return demo_capture(DEMO)


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
    assert f["data"].tolist() == [x[2] for x in lines]
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
    assert (cap.frames["data"][rtr] == "").all()


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
    assert e["row"].is_monotonic_increasing  # no timestamps: frame order decides
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


def _read_mcap(path: Path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        r = make_reader(f)
        summary = r.get_summary()
        msgs = [
            (ch.topic, sc.name, m.log_time, json.loads(m.data)) for sc, ch, m in r.iter_messages()
        ]
        f.seek(0)
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
        f.seek(0)
        att = {a.name: a.data for a in make_reader(f).iter_attachments()}
    return summary, msgs, meta, att


def test_mcap_round_trip(cap, tmp_path):
    from cananalyze.outputs.mcap.topics import write_mcap

    out = tmp_path / "demo.mcap"
    counts = write_mcap(cap, out)
    summary, msgs, meta, att = _read_mcap(out)
    topics = {ch.topic: ch for ch in summary.channels.values()}
    assert set(topics) == {
        "/node/3/tpdo1",
        "/node/3/tpdo2",
        "/node/5/tpdo2",
        "/node/3/nmt_state",
        "/node/5/nmt_state",
        "/node/10/nmt_state",
        "/canopen/events",
        "/can/frames",
    }
    stats = summary.statistics.channel_message_counts
    for topic, ch in topics.items():
        assert stats[ch.id] == counts[topic] == sum(1 for m in msgs if m[0] == topic)
    assert counts["/can/frames"] == len(cap.frames)
    assert all(c.compression == "zstd" for c in summary.chunk_indexes)
    # schema: numbers as numbers, unit in the description
    schema = json.loads(summary.schemas[topics["/node/5/tpdo2"].schema_id].data)
    assert schema["properties"]["ch1"] == {"type": "number", "description": "unit: °C"}
    # values equal the pandas API, log time = frame time in ns
    s = cap.signals
    ch1 = s[(s["node"] == 5) & (s["signal"] == "ch1")]
    got = [(m[2], m[3]["ch1"]) for m in msgs if m[0] == "/node/5/tpdo2"]
    assert [v for _, v in got] == ch1["value"].tolist()
    # each time's exact nearest ns (a Fraction is the float's exact value)
    assert [t for t, _ in got] == [round(Fraction(t) * 10**9) for t in ch1["t"].tolist()]
    ints = [m[3] for m in msgs if m[0] == "/node/3/tpdo1"]
    assert all(isinstance(v, int) for m in ints for v in m.values())
    logs = [m for m in msgs if m[0] == "/canopen/events"]
    assert {m[1] for m in logs} == {"foxglove.Log"}
    assert [m[3]["message"] for m in logs] == cap.events["message"].tolist()
    assert sorted({m[3]["level"] for m in logs}) == [2, 3, 4]
    first = logs[0]
    assert first[3]["timestamp"]["sec"] * 10**9 + first[3]["timestamp"]["nsec"] == first[2]
    assert first[3]["file"] == "demo.log" and first[3]["line"] == 1
    frames = [m[3] for m in msgs if m[0] == "/can/frames"]
    assert [m["data"] for m in frames] == cap.frames["data"].tolist()
    times = [m[2] for m in msgs]
    assert times == sorted(times)
    assert meta["cananalyze"]["version"] == cananalyze.__version__
    assert meta["cananalyze"]["source"].endswith("demo.log")
    assert [n["node"] for n in json.loads(att["nodes.json"])] == [3, 5, 10]


def test_mcap_failure_leaves_no_file(cap, tmp_path, monkeypatch):
    from cananalyze.outputs.mcap import topics as mcap_out

    def boom(*_a):
        raise RuntimeError("disk full")

    monkeypatch.setattr(mcap_out, "_metadata", boom)
    with pytest.raises(RuntimeError):
        mcap_out.write_mcap(cap, tmp_path / "x.mcap")
    assert list(tmp_path.iterdir()) == []


# --- rerun -----------------------------------------------------------------------


def _read_rrd(path: Path) -> dict[str, list[dict]]:
    from rerun.chunk import RrdReader

    rows: dict[str, list[dict]] = {}
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            rows.setdefault(chunk.entity_path, []).extend(chunk.to_record_batch().to_pylist())
    return rows


def test_rrd_round_trip(cap, tmp_path):
    from cananalyze.outputs.rerun.send import write_rrd

    out = tmp_path / "demo.rrd"
    counts = write_rrd(cap, out, bitrate=250000)
    rows = _read_rrd(out)
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
    } == set(rows)
    for path, n in counts.items():
        assert len(rows[path]) == n
    s = cap.signals
    ch3 = s[(s["node"] == 5) & (s["signal"] == "ch3")]["value"].tolist()
    assert [r["Scalars:scalars"][0] for r in rows["/node/5/tpdo2/ch3"]] == ch3
    states = [r["StateChange:state"][0] for r in rows["/node/5/nmt"]]
    assert states == ["bootup", "operational"]
    ev = rows["/events"]
    assert [r["TextLog:text"][0] for r in ev] == cap.events["message"].tolist()
    assert {r["TextLog:level"][0] for r in ev} == {"INFO", "WARN", "ERROR"}
    load = [r["Scalars:scalars"][0] for r in rows["/bus/load"]]
    assert all(0 <= x < 100 for x in load) and max(load) > 0


def test_blueprint_has_a_plot_per_pdo_and_a_lane_per_node(cap):
    """Checked against a screenshot of the viewer: a node's PDOs on one axis hid
    the digital input bytes under 10 V analogue values, and a `/node/*/nmt`
    pattern left the NMT lanes empty, so both are spelled out."""
    from cananalyze.outputs.rerun.send import blueprint

    plots, states, log = blueprint(cap).root_container.contents
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


def test_blueprint_puts_many_nodes_in_a_grid(tmp_path):
    """16 node columns side by side were a few pixels wide each in the viewer."""
    import rerun.blueprint as rrb

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from generate import generate

    from cananalyze.io.logfile import write_log
    from cananalyze.outputs.rerun.send import blueprint

    write_log(generate(3000), tmp_path / "g.log")
    c = cananalyze.load(tmp_path / "g.log", device=[f"{n}=dat7014" for n in range(1, 17)])
    plots, states, _ = blueprint(c).root_container.contents
    assert isinstance(plots, rrb.Grid)
    assert [col.name for col in plots.contents[:-1]] == [f"node {n}" for n in range(1, 17)]
    assert len(states.contents) == 16


def test_bus_load_of_steady_traffic_is_flat_to_the_end():
    """A frame every 10 ms: every window, the log's short tail included, shows the
    same load (the tail once showed a spike: a few ms ending on a frame, scaled up)."""
    from cananalyze.outputs.busload import load_series

    t = 100.0 + np.arange(101) * 0.01  # the last frame opens a 0.1 s window on its own
    starts, load = load_series(t, np.full(t.size, 111), 0.1, 250000)
    assert starts[0] == t[0] and len(starts) == 10
    assert load == pytest.approx(np.full(10, 111 / 0.01 / 250000 * 100), rel=0.15)


def test_decode_rerun_and_connect_are_exclusive(capsys):
    assert main(["decode", str(DEMO), "--rerun", "--connect", "127.0.0.1:9876"]) == 2
    assert "give one of them" in capsys.readouterr().err


# --- Parquet / CSV ---------------------------------------------------------------


def test_parquet_round_trip(cap, tmp_path):
    from cananalyze.outputs.tables.whole import TABLES, write_parquet

    rows = write_parquet(cap, tmp_path / "pq")
    for name in TABLES:
        back = pd.read_parquet(tmp_path / "pq" / f"{name}.parquet")
        orig = getattr(cap, name)
        assert rows[name] == len(orig) == len(back)
        if name in ("frames", "signals", "events"):
            pd.testing.assert_frame_equal(back, orig, check_dtype=False, check_categorical=False)
    f = pd.read_parquet(tmp_path / "pq" / "frames.parquet")
    assert (
        str(f["node"].dtype) == "Int16"
        and f["node"].isna().sum() == cap.frames["node"].isna().sum()
    )


def test_parquet_and_csv_with_mixed_findings_values(tmp_path):
    """Findings' measured/expected hold numbers and text (160.3 ms, "0xFFA8", "cleared"):
    Parquet needs one type per column, so they are written as text."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from generate import generate

    from cananalyze.io.logfile import write_log
    from cananalyze.outputs.tables.whole import write_csv, write_parquet

    write_log(generate(5000), tmp_path / "g.log")
    c = cananalyze.load(tmp_path / "g.log", device=[f"{n}=dat7014" for n in range(1, 17)])
    kinds = {type(v) for v in c.findings["measured"] if v is not None}
    assert str in kinds and kinds & {int, float}  # the case that failed
    rows = write_parquet(c, tmp_path / "pq")
    back = pd.read_parquet(tmp_path / "pq" / "findings.parquet")
    assert rows["findings"] == len(back) == len(c.findings)
    assert back["measured"].tolist() == [
        None if v is None else str(v) for v in c.findings["measured"]
    ]
    assert back["rule"].tolist() == c.findings["rule"].tolist()
    write_csv(c, tmp_path / "csv")
    assert len(pd.read_csv(tmp_path / "csv" / "findings.csv")) == len(c.findings)


def test_csv_tables(cap, tmp_path):
    from cananalyze.outputs.tables.whole import write_csv

    write_csv(cap, tmp_path / "csv")
    f = pd.read_csv(tmp_path / "csv" / "frames.csv", keep_default_na=False, dtype={"data": str})
    assert f["data"].tolist() == cap.frames["data"].tolist()
    s = pd.read_csv(tmp_path / "csv" / "signals.csv")
    assert s["value"].tolist() == pytest.approx(cap.signals["value"].tolist())


# --- CLI -------------------------------------------------------------------------


def test_cli_export_all_outputs(tmp_path, capsys):
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
    summary, msgs, _, _ = _read_mcap(tmp_path / "a.mcap")
    assert sum(1 for m in msgs if m[0] == "/can/frames") == 185
    assert len(_read_rrd(tmp_path / "a.rrd")["/events"]) == 19
    assert len(pd.read_parquet(tmp_path / "pq" / "sdo.parquet")) == 7
    assert (tmp_path / "csv" / "nodes.csv").exists()
    err = capsys.readouterr().err
    assert "exported 185 frames" in err and "\x1b" not in err  # no progress bar off a terminal


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
    _, msgs, _, _ = _read_mcap(tmp_path / "d.mcap")
    assert sum(1 for m in msgs if m[0] == "/canopen/events") == 19


def test_bulk_export_of_generated_log(tmp_path):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from generate import generate

    from cananalyze.io.logfile import write_log
    from cananalyze.outputs.mcap.topics import write_mcap
    from cananalyze.outputs.rerun.send import write_rrd

    batch = generate(20000)
    log = tmp_path / "g.log"
    write_log(batch, log)
    c = cananalyze.load(log)
    assert len(c) == 20000
    counts = write_mcap(c, tmp_path / "g.mcap")
    assert counts["/can/frames"] == 20000
    assert counts["/canopen/events"] == len(c.events)
    emcy = int(((batch.can_id & 0x780) == 0x080).sum() - (batch.can_id == 0x080).sum())
    assert (c.events["kind"] == "emcy").sum() == emcy
    rrd = write_rrd(c, tmp_path / "g.rrd")
    assert rrd["/events"] == len(c.events)
