"""`cananalyze live` end to end: a replayed log on an slcan pseudo-terminal in one
process, the live command in another; decoded lines and recordings are checked
against what was sent, also when the session is interrupted or the adapter vanishes."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import can
import pytest
from conftest import ROOT, SAMPLES
from helpers.live_slcan import start_live

from cananalyze.formats.mcap_frames import log_time_ns
from cananalyze.formats.source import read_all
from cananalyze.outputs.text.writer import TextWriter
from cananalyze.pipeline import Options, build_decoder
from cananalyze.sim.slcan_replay import SlcanAdapter, replay

DEMO = SAMPLES / "demo.log"


def _start_live(args: list[str]) -> tuple[subprocess.Popen, SlcanAdapter, int]:
    return start_live(args)


def _frame_part(line: str) -> str:
    """A decode line without its time and channel columns (those differ live)."""
    return line.split(None, 2)[2]


def _no_latency(line: str) -> str:
    return re.sub(r", latency [0-9.]+ ms", "", line)


def _sent() -> list[can.Message]:
    return list(can.LogReader(str(DEMO)))


def _same_frames(got: list[can.Message], sent: list[can.Message]) -> None:
    assert len(got) == len(sent)
    for g, s in zip(got, sent, strict=True):
        assert (g.arbitration_id, g.is_extended_id, g.is_remote_frame, g.dlc) == (
            s.arbitration_id,
            s.is_extended_id,
            s.is_remote_frame,
            s.dlc,
        )
        if not s.is_remote_frame:
            assert bytes(g.data) == bytes(s.data)


@pytest.mark.slow
def test_plain_decode_and_candump_record_match_what_was_sent(tmp_path):
    rec = tmp_path / "live.log"
    proc, adapter, slave = _start_live(["--plain", "--record", str(rec)])
    sent = replay(adapter, str(DEMO), timed=True)  # ~2 s with the log's own timing
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert sent == 185

    # offline decode of the same log, same writer
    import io

    buf = io.StringIO()
    dec = build_decoder(Options())  # as `cananalyze decode` builds it
    TextWriter(buf).write(dec.decode(read_all(DEMO)))
    TextWriter(buf).write(dec.finish())
    expected = [_frame_part(x) for x in buf.getvalue().splitlines() if "└─" not in x]
    assert len(expected) == 185
    # SDO transaction records: same, but latencies are measured on the live clock
    expected_recs = [_no_latency(x) for x in buf.getvalue().splitlines() if "└─" in x]
    assert len(expected_recs) == 7  # 5 reads, one abort, one write
    lines = out.splitlines()
    frame_lines = [x for x in lines[: lines.index("frames: 185")] if "└─" not in x]
    assert [_frame_part(x) for x in frame_lines] == expected
    recs = [_no_latency(x) for x in lines[: lines.index("frames: 185")] if "└─" in x]
    assert recs == expected_recs
    assert any("0x1008:00 Manufacturer device name segmented -> ok: 'DAT7014'" in x for x in recs)
    assert {x.split()[1] for x in frame_lines} == {"pts" + os.ttyname(slave).rpartition("/")[2]}
    assert any("EMCY 0x8100" in x for x in frame_lines)
    # the summary at exit
    assert "frames per node:" in out and "node   5:" in out
    assert f"recorded 185 frames to {rec}" in err

    _same_frames(list(can.LogReader(str(rec))), _sent())
    assert [m.timestamp for m in can.LogReader(str(rec))] == sorted(
        m.timestamp for m in can.LogReader(str(rec))
    )


@pytest.mark.parametrize(("suffix", "sig"), [(".blf", signal.SIGINT), (".mcap", signal.SIGTERM)])
@pytest.mark.slow
def test_interrupted_session_leaves_a_valid_recording(tmp_path, suffix, sig):
    rec = tmp_path / f"live{suffix}"
    proc, adapter, _ = _start_live(["--plain", "--record", str(rec)])
    sent = _sent()[:120]
    for msg in sent:
        adapter.send(msg)
    time.sleep(1.0)  # the bus is still open when the signal comes
    assert proc.poll() is None
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "frames: 120" in out
    if suffix == ".blf":
        got = list(can.BLFReader(str(rec)))
    else:
        from mcap.reader import make_reader

        got = []
        with open(rec, "rb") as f:
            reader = make_reader(f, validate_crcs=True)
            summary = reader.get_summary()
            assert summary is not None and summary.statistics.message_count == 120
            assert summary.chunk_indexes  # chunked and indexed
            times = []
            for schema, channel, message in reader.iter_messages(topics=["/can/frames"]):
                assert schema.name == "cananalyze.Frame" and channel.message_encoding == "json"
                d = json.loads(message.data)
                assert list(d) == ["channel", "can_id", "dlc", "data", "flags", "service", "node"]
                assert message.publish_time == message.log_time
                times.append(message.log_time)
                got.append(
                    can.Message(
                        arbitration_id=d["can_id"],
                        is_extended_id=bool(d["flags"] & 1),
                        is_remote_frame=bool(d["flags"] & 2),
                        dlc=d["dlc"],
                        data=bytes.fromhex(d["data"]),
                    )
                )
            assert times == sorted(times) and abs(times[-1] / 1e9 - time.time()) < 120
        # and cananalyze reads its own recording back
        back = read_all(rec)
        assert back.can_id.tolist() == [m.arbitration_id for m in got]
        assert log_time_ns(back.t).tolist() == times
    _same_frames(got, sent)


@pytest.mark.slow
def test_adapter_unplugged_gives_one_line_and_a_valid_recording(tmp_path):
    rec = tmp_path / "cut.blf"
    proc, adapter, slave = _start_live(["--plain", "--record", str(rec)])
    sent = _sent()[:50]
    for msg in sent:
        adapter.send(msg)
    time.sleep(1.0)
    # pull the plug: both ends of the pty go away, reads on the device fail
    os.close(adapter.fd)
    os.close(slave)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 2
    errors = [x for x in err.splitlines() if x.startswith("cananalyze: error:")]
    assert len(errors) == 1 and "interface error" in errors[0], err
    assert "Traceback" not in err
    assert "frames: 50" in out
    _same_frames(list(can.BLFReader(str(rec))), sent)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["-i", "nosuchbus", "-c", "x"], "nosuchbus"),
        (["-i", "slcan", "-c", "/dev/does-not-exist"], "/dev/does-not-exist"),
        (["-i", "virtual", "-c", "x", "--record", "out.txt"], "--record"),
        (["-i", "virtual", "-c", "x", "--filter", "zz"], "--filter"),
    ],
)
def test_interface_and_usage_errors_are_one_line(tmp_path, args, needle):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run(
        [sys.executable, "-m", "cananalyze", "live", *args, "--plain"],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=60,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cananalyze: error:") and needle in lines[0], (
        proc.stderr
    )


def test_duration_stops_by_itself():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t = time.monotonic()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "cananalyze",
            "live",
            "-i",
            "virtual",
            "-c",
            "quiet",
            "--duration",
            "0.5",
        ],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert time.monotonic() - t < 10
    assert "frames: 0" in proc.stdout  # stdout is a pipe: plain mode, then the summary


def test_live_without_an_interface_says_how_to_name_one(tmp_path):
    """No -i, no python-can configuration (an empty home, no CAN_* variables): one line
    naming -i/-c and python-can's configuration, not 'Unknown interface type "None"'."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if not k.startswith("CAN_")}
    env["HOME"] = str(tmp_path)
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", "live"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=60,
    )
    assert r.returncode == 2
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith("cananalyze: error: no CAN interface given: name one with -i/")
    assert "~/.canrc" in line and '"None"' not in line
