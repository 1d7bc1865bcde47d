"""The streaming MCAP writer (`export --mcap`, `decode --mcap`) writes the messages,
schemas, metadata and attachments of the Capture path (`write_mcap`), whatever the
batch size; a failed export leaves no file."""

from __future__ import annotations

import collections
import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, SAMPLES, generated_log, real_file
from mcap.reader import make_reader
from test_table_stream import DEVICES, _args, _batches, given_profiles

from cananalyze.capture import Collector
from cananalyze.errors import ProblemLog
from cananalyze.outputs.mcap import stream as mcap_stream
from cananalyze.outputs.mcap.stream import StreamMcap
from cananalyze.outputs.mcap.topics import write_mcap

NETWORK = str(SAMPLES / "network.toml")


def _stream(log: Path, out: Path, size: int | None = None, **kw) -> dict[str, int]:
    profiles = given_profiles(_args(log, **kw))
    with StreamMcap(out, source=str(log), network=kw.get("network") or "", profiles=profiles) as s:
        for batch in _batches(log, size, **kw):
            s.add(batch)
        return s.close(0)


def _reference(log: Path, out: Path, size: int | None = None, **kw) -> dict[str, int]:
    collector = Collector(str(log))
    for batch in _batches(log, size, **kw):
        collector.add(batch)
    cap = collector.capture(ProblemLog(), kw.get("network") or "", given_profiles(_args(log, **kw)))
    return write_mcap(cap, out)


def read(path: Path):
    """(messages per topic in file order, schema per topic, metadata, attachments, summary)."""
    per: dict[str, list] = collections.defaultdict(list)
    schemas = {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for sc, ch, m in reader.iter_messages(log_time_order=False):
            per[ch.topic].append((m.log_time, m.publish_time, m.data))
            schemas[ch.topic] = (sc.name, sc.encoding, json.loads(sc.data))
        summary = reader.get_summary()
        f.seek(0)
        meta = {m.name: m.metadata for m in make_reader(f).iter_metadata()}
        f.seek(0)
        att = {a.name: a.data for a in make_reader(f).iter_attachments()}
    return per, schemas, meta, att, summary


def assert_same_mcap(ref: Path, new: Path) -> None:
    a, b = read(ref), read(new)
    assert set(a[0]) == set(b[0])
    for topic in a[0]:
        # an SDO transfer that ends in a later batch is written with that batch: the
        # topics hold the same messages, each in time order within its chunk
        assert sorted(a[0][topic]) == sorted(b[0][topic]), topic
    assert a[1] == b[1]
    assert a[2] == b[2] and a[3] == b[3]
    stats_a, stats_b = a[4].statistics, b[4].statistics
    topic_of = {c.id: c.topic for c in b[4].channels.values()}
    counts = {topic_of[k]: v for k, v in stats_b.channel_message_counts.items()}
    assert counts == {t: len(m) for t, m in b[0].items()}
    assert stats_a.message_count == stats_b.message_count
    assert (stats_a.message_start_time, stats_a.message_end_time) == (
        stats_b.message_start_time,
        stats_b.message_end_time,
    )


def _both(tmp_path: Path, log: Path, size: int | None = None, **kw) -> dict[str, int]:
    ref = _reference(log, tmp_path / "ref.mcap", size, **kw)
    new = _stream(log, tmp_path / "new.mcap", size, **kw)
    assert new == ref
    assert_same_mcap(tmp_path / "ref.mcap", tmp_path / "new.mcap")
    return new


@pytest.mark.parametrize("name", ["demo.log", "faults.log", "commissioning.log", "faults.blf"])
def test_samples_same_mcap(tmp_path, name):
    counts = _both(tmp_path, SAMPLES / name, network=NETWORK)
    assert counts["/can/frames"] > 0 and counts["/canopen/events"] > 0


@pytest.mark.parametrize("size", [1, 7, 1000])
def test_batch_size_invariance(tmp_path, size):
    counts = _both(tmp_path, SAMPLES / "faults.log", size=size, network=NETWORK)
    assert any(t.endswith("nmt_state") for t in counts)


def test_generated_devices_small_batches(tmp_path):
    """16 nodes with profiles: signal topics, SDO transfers and EMCY cut across batches."""
    counts = _both(tmp_path, generated_log(tmp_path, 30000), size=997, device=DEVICES)
    assert sum(1 for t in counts if t.endswith("pdo2")) == 16
    per = read(tmp_path / "new.mcap")[0]
    frames = [t for t, _, _ in per["/can/frames"]]
    assert frames == sorted(frames)  # the frames topic is in time order across chunks


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan2.trc",
        "hilch__canopen-message-interpreter/ixxat1.trc",
        "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test1.log",
    ],
)
def test_real_logs_same_mcap(tmp_path, rel):
    _both(tmp_path, real_file(rel), size=512)


def test_end_of_log_records_keep_their_line(tmp_path):
    """SDO transfers the end of the log completes (a timeout) sit on the last frame's row,
    which belongs to the previous batch: their events still carry its input line."""
    log = tmp_path / "t.log"
    log.write_text(
        "(1.000000) can0 605#4018100100000000\n"  # upload request 0x1018:01, never answered
        "(1.500000) can0 701#05\n"
    )
    _both(tmp_path, log)
    events = read(tmp_path / "new.mcap")[0]["/canopen/events"]
    docs = [json.loads(d) for _, _, d in events]
    assert docs and docs[-1]["line"] == 2 and docs[-1]["file"] == "t.log"


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


def test_cli_export_and_decode_write_the_same_mcap(tmp_path):
    """export --mcap (with --parquet beside it) and decode --mcap stream the same file as
    the Capture path; the nodes attachment names the given device profiles."""
    log = SAMPLES / "faults.log"
    r = _cli(
        "export",
        str(log),
        "--no-check",
        "--mcap",
        str(tmp_path / "e.mcap"),
        "--parquet",
        str(tmp_path),
    )
    assert r.returncode == 0, r.stderr
    r = _cli("decode", str(log), "--mcap", str(tmp_path / "d.mcap"), "-o", str(tmp_path / "d.txt"))
    assert r.returncode == 0, r.stderr
    _reference(log, tmp_path / "ref.mcap")
    assert_same_mcap(tmp_path / "ref.mcap", tmp_path / "e.mcap")
    assert_same_mcap(tmp_path / "ref.mcap", tmp_path / "d.mcap")
    assert (tmp_path / "frames.parquet").exists() and (tmp_path / "d.txt").stat().st_size > 0
    gen = generated_log(tmp_path, 3000)
    r = _cli("export", str(gen), "--mcap", str(tmp_path / "g.mcap"), "--device", "3=dat7014")
    assert r.returncode == 0, r.stderr
    nodes = json.loads(read(tmp_path / "g.mcap")[3]["nodes.json"])
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
    per, _, meta, _, _ = read(tmp_path / "b.mcap")
    assert meta["cananalyze"]["skipped_input"] == "1" and meta["cananalyze"]["frames"] == "2"
    assert len(per["/can/frames"]) == 2 and (tmp_path / "b.rrd").stat().st_size > 0


def test_disk_failing_in_the_chunk_thread(tmp_path, monkeypatch, capsys):
    """A write that fails on the MCAP writer's own thread (a full disk) stops the export
    with one line naming the error, and leaves no file behind."""
    from cananalyze.cli.main import main
    from cananalyze.outputs.mcap import bulk as mcap_bulk

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
