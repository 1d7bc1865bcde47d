"""`export --mcap` and `decode --mcap` write the log `load()` decodes, read back with the
`mcap` package's reader: a topic per PDO with its signal values, NMT states, the event log,
every frame, the metadata and nodes attachment; the same file whatever the batch size; a
failed export leaves no file."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, SAMPLES, generated_log, real_file
from exported import (
    DEVICES,
    NETWORK,
    assert_mcap_is,
    assert_same_mcap,
    decoded_batches,
    export,
    load_cut,
    read_mcap,
)

import cananalyze
from cananalyze.outputs.mcap import stream as mcap_stream
from cananalyze.outputs.mcap.stream import StreamMcap


def _stream(log: Path, out: Path, size: int | None = None, **kw) -> dict[str, int]:
    """The MCAP writer fed directly (no run, no rules), batches of `size` frames."""
    with StreamMcap(out, source=str(log), network=kw.get("network") or "") as s:
        for batch in decoded_batches(log, size, **kw):
            s.add(batch)
        return s.close(0)


def _as_load(tmp_path: Path, log: Path, size: int | None = None, **kw):
    """Export the log as MCAP; it must hold load()'s log of the same options."""
    out = export(log, tmp_path, ("mcap",), size, **kw)["mcap"]
    return assert_mcap_is(load_cut(log, size, **kw), out)


@pytest.mark.parametrize("name", ["demo.log", "faults.log", "commissioning.log", "faults.blf"])
def test_samples_mcap_is_load(tmp_path, name):
    m = _as_load(tmp_path, SAMPLES / name, network=NETWORK)
    assert m.messages["/can/frames"] and m.messages["/canopen/events"]
    if name.startswith("faults"):  # samples/README.md: 5 EMCY, node 7's never reset
        emcy = [d for d in m.docs("/canopen/events") if "EMCY" in d["message"]]
        assert sum(d["message"].startswith("node 7: EMCY 0xFF00") for d in emcy) == 1
        assert any(d["message"].startswith("[emcy]") for d in m.docs("/canopen/events"))


@pytest.mark.parametrize("size", [1, 7, 1000])
@pytest.mark.slow
def test_batch_size_invariance(tmp_path, size):
    """Cut anywhere (a frame at a time, like live), the messages are those of one batch."""
    log = SAMPLES / "faults.log"
    whole = export(log, tmp_path / "whole", ("mcap",), network=NETWORK)["mcap"]
    m = _as_load(tmp_path / "cut", log, size, network=NETWORK)
    assert any(t.endswith("nmt_state") for t in m.messages)
    assert_same_mcap(whole, tmp_path / "cut" / "x.mcap")


@pytest.mark.slow
def test_generated_devices_small_batches(tmp_path):
    """16 nodes with profiles: signal topics, SDO transfers and EMCY cut across batches."""
    m = _as_load(tmp_path, generated_log(tmp_path, 30000), 997, device=DEVICES)
    assert sum(1 for t in m.messages if t.endswith("pdo2")) == 16


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan2.trc",
        "hilch__canopen-message-interpreter/ixxat1.trc",
        "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log",
    ],
)
def test_real_logs_mcap_is_load(tmp_path, rel):
    _as_load(tmp_path, real_file(rel), size=512)


def test_end_of_log_records_keep_their_line(tmp_path):
    """SDO transfers the end of the log completes (a timeout) sit on the last frame's row,
    which belongs to the previous batch: their events still carry its input line."""
    log = tmp_path / "t.log"
    log.write_text(
        "(1.000000) can0 605#4018100100000000\n"  # upload request 0x1018:01, never answered
        "(1.500000) can0 701#05\n"
    )
    m = _as_load(tmp_path, log)
    (timeout,) = [d for d in m.docs("/canopen/events") if d["message"].startswith("SDO upload")]
    assert "timeout" in timeout["message"]
    assert timeout["line"] == 2 and timeout["file"] == "t.log"


def test_failed_export_leaves_no_file(tmp_path, monkeypatch):
    def boom(*_a, **_k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(mcap_stream, "write_merged", boom)
    log = SAMPLES / "faults.log"
    with pytest.raises(RuntimeError, match="disk full"):
        _stream(log, tmp_path / "x.mcap", size=50, network=NETWORK)
    assert list(tmp_path.iterdir()) == []


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, cwd=ROOT
    )


@pytest.mark.slow
def test_cli_export_and_decode_write_the_same_mcap(tmp_path):
    """export --mcap (with --parquet beside it) writes load()'s log, findings included;
    decode --mcap (no rules) the same messages but the findings; the nodes attachment names
    the given device profiles."""
    log = SAMPLES / "faults.log"
    r = _cli("export", str(log), "--mcap", str(tmp_path / "e.mcap"), "--parquet", str(tmp_path))
    assert r.returncode == 0, r.stderr
    m = assert_mcap_is(cananalyze.load(log), tmp_path / "e.mcap")
    findings = [d for d in m.docs("/canopen/events") if d["message"].startswith("[")]
    assert findings and len(findings) == len(cananalyze.load(log).findings)
    r = _cli("decode", str(log), "--mcap", str(tmp_path / "d.mcap"), "-o", str(tmp_path / "d.txt"))
    assert r.returncode == 0, r.stderr
    r = _cli("export", str(log), "--no-check", "--mcap", str(tmp_path / "n.mcap"))
    assert r.returncode == 0, r.stderr
    assert_same_mcap(tmp_path / "n.mcap", tmp_path / "d.mcap")
    events = read_mcap(tmp_path / "d.mcap").messages["/canopen/events"]
    assert len(events) == len(m.messages["/canopen/events"]) - len(findings)
    assert (tmp_path / "frames.parquet").exists() and (tmp_path / "d.txt").stat().st_size > 0
    gen = generated_log(tmp_path, 3000)
    r = _cli("export", str(gen), "--mcap", str(tmp_path / "g.mcap"), "--device", "3=dat7014")
    assert r.returncode == 0, r.stderr
    nodes = json.loads(read_mcap(tmp_path / "g.mcap").attachments["nodes.json"])
    assert {n["node"]: n["profile"] for n in nodes}[3] == "dat7014"


def test_cli_export_counts_skipped_lines(tmp_path):
    """Lenient by default: a bad line is skipped, counted in the MCAP metadata and named
    on stderr; the frames around it are all there."""
    log = tmp_path / "bad.log"
    log.write_text("(1.000000) can0 701#05\n(1.100000) can0 70Z#05\n(1.200000) can0 181#0102\n")
    r = _cli(
        "export", str(log), "--mcap", str(tmp_path / "b.mcap"), "--rrd", str(tmp_path / "b.rrd")
    )
    assert r.returncode == 0, r.stderr
    assert "bad.log" in r.stderr and "line 2" in r.stderr
    m = assert_mcap_is(cananalyze.load(log), tmp_path / "b.mcap")
    assert m.metadata["cananalyze"]["skipped_input"] == "1"
    assert len(m.messages["/can/frames"]) == 2 and (tmp_path / "b.rrd").stat().st_size > 0


def test_disk_failing_in_the_chunk_thread(tmp_path, monkeypatch, capsys):
    """A write that fails on the MCAP writer's own thread (a full disk) stops the export
    with one line naming the error, and leaves no file behind."""
    from cananalyze.cli.main import main
    from cananalyze.formats import mcap_bulk

    def full(self, *_a):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mcap_bulk.BulkMcapWriter, "_write_chunk", full)
    out = tmp_path / "out"
    out.mkdir()
    rc = main(["export", str(SAMPLES / "faults.log"), "--mcap", str(out / "x.mcap"), "-q"])
    err = capsys.readouterr().err
    assert rc != 0 and "Traceback" not in err
    assert err.strip() == f"cananalyze: error: {out / 'x.mcap'}: No space left on device"
    assert list(out.iterdir()) == []
