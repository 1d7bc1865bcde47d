"""Bus load per node and the longest burst (issue 40 item 3), in `decode --summary` (text and
JSON), `check --timing` and `load()`, against bits counted by hand: at 125 kbit/s a heartbeat (1 byte) is
47 + 8 = 55 nominal bits, an 8-byte PDO 47 + 64 = 111 bits, 888 us on the wire."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

import cananalyze
from tests.outputs.test_report import parse

RATE = 125_000
WIRE_8 = 111 / RATE  # an 8-byte frame's time on the wire


def _log(path: Path) -> Path:
    frames = [(0.1 * k, "705#05") for k in range(21)]
    frames += [(0.1 * k + 0.05, "706#05") for k in range(21)]
    # five PDOs back to back from +1.02 s: each ends one frame time after the one before
    burst = ["185", "186", "185", "186", "185"]
    frames += [(1.02 + k * WIRE_8, f"{cob}#{k:02X}00000000000000") for k, cob in enumerate(burst)]
    # a pair 1 ms apart (idle bus between): no burst
    frames += [(1.5, "185#0100000000000000"), (1.501 + WIRE_8, "186#0100000000000000")]
    path.write_text("".join(f"({100 + t:.6f}) can0 {f}\n" for t, f in sorted(frames)))
    return path


# frames each node sent, bits by hand, over the log's 2.05 s
NODE5 = (21 + 4, 21 * 55 + 4 * 111)
NODE6 = (21 + 3, 21 * 55 + 3 * 111)
SPAN = 2.05


def _share(bits: int) -> float:
    return bits / (RATE * SPAN) * 100


def _summary(log: Path, *extra: str) -> str:
    return _cli("decode", str(log), "--summary", *extra)


def _cli(*args: str, ok: tuple[int, ...] = (0,)) -> str:
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert r.returncode in ok, r.stderr
    return r.stdout


def test_summary_text_has_each_node_s_load_and_the_longest_burst(tmp_path):
    out = _summary(_log(tmp_path / "b.log"), "--bitrate", str(RATE)).splitlines()
    at = out.index("bus load per node (frames it sent, nominal bits):")
    assert out[at + 1].split() == ["node", "5", f"{_share(NODE5[1]):.2f}", "%"]
    assert out[at + 2].split() == ["node", "6", f"{_share(NODE6[1]):.2f}", "%"]
    burst = [x for x in out if x.startswith("longest burst")]
    assert burst == ["longest burst: 5 frames back to back, +1.020000 s to +1.023552 s (3.552 ms)"]


def test_summary_json_and_load_agree_with_the_bits_by_hand(tmp_path):
    log = _log(tmp_path / "b.log")
    rec = json.loads(_summary(log, "--bitrate", str(RATE), "--format", "jsonl"))
    assert rec["bus_load_percent_per_node"] == {
        "5": round(_share(NODE5[1]), 3),
        "6": round(_share(NODE6[1]), 3),
    }
    assert rec["longest_burst"]["frames"] == 5
    assert rec["longest_burst"]["t_start"] == pytest.approx(101.02)
    cap = cananalyze.load(str(log))
    df = cap.bus_load_per_node(RATE)
    assert df[["node", "frames", "bits"]].values.tolist() == [[5, *NODE5], [6, *NODE6]]
    assert df["load_percent"].tolist() == pytest.approx([_share(NODE5[1]), _share(NODE6[1])])
    assert cap.bus_load_per_node()["load_percent"].isna().all()  # no bitrate: not known
    burst = cap.longest_burst(RATE)["can0"]
    assert burst["frames"] == 5
    assert burst["t_end"] - burst["t_start"] == pytest.approx(4 * WIRE_8, abs=2e-6)
    assert cap.longest_burst() == {}


def test_without_a_bitrate_the_summary_is_as_before(tmp_path):
    out = _summary(_log(tmp_path / "b.log"))
    assert "bus load per node" not in out and "longest burst" not in out
    rec = json.loads(_summary(_log(tmp_path / "b.log"), "--format", "jsonl"))
    assert "bus_load_percent_per_node" not in rec and "longest_burst" not in rec


def _load_lines(out: list[str]) -> list[str]:
    at = out.index("bus load per node (frames it sent, nominal bits):")
    return out[at : at + 4]


def test_check_timing_has_the_summary_s_node_load_and_burst(tmp_path):
    log = _log(tmp_path / "b.log")
    out = _cli("check", str(log), "--timing", "--bitrate", str(RATE), "--no-color", ok=(0, 1))
    lines = _load_lines(out.splitlines())
    assert lines[1].split() == ["node", "5", f"{_share(NODE5[1]):.2f}", "%"]
    assert lines[2].split() == ["node", "6", f"{_share(NODE6[1]):.2f}", "%"]
    assert lines[3] == "longest burst: 5 frames back to back, +1.020000 s to +1.023552 s (3.552 ms)"
    summary = _summary(log, "--bitrate", str(RATE)).splitlines()
    assert _load_lines(summary) == lines
    # the network file's bitrate when none is given; none at all: no load, as the summary
    net = tmp_path / "net.toml"
    net.write_text(f"bitrate = {RATE}\n")
    out = _cli("check", str(log), "--timing", "--network", str(net), "--no-color", ok=(0, 1))
    assert _load_lines(out.splitlines()) == lines
    out = _cli("check", str(log), "--timing", "--no-color", ok=(0, 1))
    assert "SYNC" in out or "heartbeat" in out  # the timing is printed
    assert "bus load per node" not in out and "longest burst" not in out
    out = _cli("check", str(log), "--bitrate", str(RATE), "--no-color", ok=(0, 1))
    assert "bus load per node" not in out  # only with --timing


def _node_table(page: Path) -> list[list[str]] | None:
    _, tables, _ = parse(page)  # the report tests' reader (html.parser)
    return next((t for t in tables.tables if t and t[0][0] == "node" and "mean load" in t[0]), None)


def test_report_has_each_node_s_load(tmp_path):
    log, page = _log(tmp_path / "b.log"), tmp_path / "b.html"
    _cli("report", str(log), "-o", str(page), "--bitrate", str(RATE), "-q", ok=(0, 1))
    assert _node_table(page) == [
        ["node", "frames it sent", "mean load"],
        ["node 5", str(NODE5[0]), f"{_share(NODE5[1]):.2f}%"],
        ["node 6", str(NODE6[0]), f"{_share(NODE6[1]):.2f}%"],
    ]
    _, tables, _ = parse(page)
    burst = next(t for t in tables.tables if t and t[0][0] == "channel" and "length" in t[0])
    assert burst == [  # the summary's "longest burst" line
        ["channel", "frames back to back", "from", "length"],
        ["can0", "5", "+1.020000 s", "3.552 ms"],
    ]
    _cli("report", str(log), "-o", str(page), "-q", ok=(0, 1))
    assert _node_table(page) is None  # no bitrate: no share
    _, tables, _ = parse(page)
    assert not [t for t in tables.tables if t and "frames back to back" in t[0]]


def _export(log: Path, out: Path, *extra: str) -> None:
    _cli(
        "export", str(log), "--parquet", str(out / "pq"), "--csv", str(out / "csv"),
        "--mcap", str(out / "b.mcap"), *extra, ok=(0, 1),
    )  # fmt: skip


def test_the_tables_carry_each_node_s_load_and_the_longest_burst(tmp_path):
    """Issue 40 item 3 in the tables: the nodes table's `bits` and `bus_load_percent` and a
    `burst` event, read back by pyarrow, DuckDB and the mcap library."""
    import duckdb
    import pyarrow.parquet as pq
    from exported import read_mcap

    log = _log(tmp_path / "b.log")
    _export(log, tmp_path, "--bitrate", str(RATE))
    want = {5: (NODE5[1], _share(NODE5[1])), 6: (NODE6[1], _share(NODE6[1]))}
    nodes = pq.read_table(tmp_path / "pq" / "nodes.parquet").to_pylist()
    got = {r["node"]: (r["bits"], r["bus_load_percent"]) for r in nodes}
    assert got == {n: (b, pytest.approx(p)) for n, (b, p) in want.items()}
    csv = duckdb.sql(
        f"select node, bits, bus_load_percent from read_csv('{tmp_path / 'csv' / 'nodes.csv'}')"
    ).fetchall()
    assert {n: (b, p) for n, b, p in csv} == got
    meta = json.loads(read_mcap(tmp_path / "b.mcap").attachments["nodes.json"])
    assert {r["node"]: (r["bits"], r["bus_load_percent"]) for r in meta} == got
    # the longest burst: one event at its first frame, in the summary's words
    events = duckdb.sql(
        f"select t, node, level, message, row from '{tmp_path / 'pq' / 'events.parquet'}' "
        "where kind = 'burst'"
    ).fetchall()
    assert events == [
        (
            pytest.approx(101.02),
            None,
            "info",
            "longest burst: 5 frames back to back (3.552 ms)",
            None,
        )
    ]
    mcap_events = [
        json.loads(d) for _, _, d in read_mcap(tmp_path / "b.mcap").messages["/canopen/events"]
    ]
    # Foxglove's Log schema: a bus-wide event is named by its kind
    assert [e["message"] for e in mcap_events if e["name"] == "burst"] == [events[0][3]]
    # load() says the same
    cap = cananalyze.load(str(log), bitrate=RATE)
    assert cap.nodes[["bits", "bus_load_percent"]].to_dict("index") == {
        n: {"bits": b, "bus_load_percent": pytest.approx(p)} for n, (b, p) in want.items()
    }
    assert cap.events[cap.events.kind == "burst"].message.tolist() == [events[0][3]]


def test_without_a_bitrate_the_tables_have_the_bits_but_no_share_and_no_burst(tmp_path):
    import pyarrow.parquet as pq

    log = _log(tmp_path / "b.log")
    _export(log, tmp_path)
    nodes = pq.read_table(tmp_path / "pq" / "nodes.parquet").to_pylist()
    assert [(r["node"], r["bits"], r["bus_load_percent"]) for r in nodes] == [
        (5, NODE5[1], None),
        (6, NODE6[1], None),
    ]
    kinds = pq.read_table(tmp_path / "pq" / "events.parquet").column("kind").to_pylist()
    assert "burst" not in kinds
    lines = _cli("decode", str(log), "--format", "jsonl").splitlines()
    assert not [x for x in lines if '"kind":"burst"' in x]
    lines = _cli("decode", str(log), "--format", "jsonl", "--bitrate", str(RATE)).splitlines()
    burst = [json.loads(x) for x in lines if '"kind":"burst"' in x]
    assert burst == [
        {"kind": "burst", "frames": 5, "t_start": 101.02, "t_end": 101.023552, "ms": 3.552}
    ]


def test_the_docs_tables_example_is_the_output():
    """docs/decoding.md's nodes table and burst event on samples/commissioning.log are what
    load() gives (the page's `>>>` lines run here)."""
    docs = (ROOT / "docs" / "decoding.md").read_text(encoding="utf-8")
    block = docs.split('>>> cap = cananalyze.load("samples/commissioning.log"', 1)[1]
    block = block.split("```", 1)[0].splitlines()[1:]
    cap = cananalyze.load(
        str(ROOT / "samples" / "commissioning.log"), network=str(ROOT / "samples" / "network.toml")
    )
    table = cap.nodes[["frames", "bits", "bus_load_percent"]].round(2).to_string()
    burst = repr(cap.events.query("kind == 'burst'").message.tolist())
    assert block == [
        '>>> cap.nodes[["frames", "bits", "bus_load_percent"]].round(2)',
        *table.splitlines(),
        """>>> cap.events.query("kind == 'burst'").message.tolist()""",
        burst,
    ]
    assert burst == "['longest burst: 6 frames back to back (0.948 ms)']"
