"""MCAP as an input (`io/mcap.py`), and the one /can/frames schema export and live
recording share (`outputs/mcap/frames.py`).

Oracles are independent readers: the `mcap` package reads what was written, python-can
reads the original logs, and `cananalyze decode` of the original log is what decoding
the MCAP must repeat. Damaged files (cut off, a corrupt chunk, broken documents, no
frames topic) must give their frames before the damage and one line, never a traceback.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
from fractions import Fraction
from pathlib import Path

import can
import numpy as np
import pytest
from conftest import ROOT, SAMPLES, real_file
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import Writer

from cananalyze.cli.main import main
from cananalyze.core.columns.json_text import Texts
from cananalyze.core.errors import InputError
from cananalyze.core.frames import (
    FLAG_BRS,
    FLAG_ERR,
    FLAG_ESI,
    FLAG_EXT,
    FLAG_FD,
    FLAG_RTR,
    FLAG_TX,
    FrameBatch,
    concat,
    set_row,
)
from cananalyze.formats.live import LiveSource
from cananalyze.formats.logfile import write_log
from cananalyze.formats.logs import mcap as mcap_in
from cananalyze.formats.logs._pycan_writer import to_messages
from cananalyze.formats.mcap_bulk import BulkMcapWriter
from cananalyze.formats.mcap_frames import (
    FRAME_FIELDS,
    FRAME_SCHEMA,
    FRAMES_TOPIC,
    frame_payloads,
    log_time_ns,
    seconds,
)
from cananalyze.formats.record import FrameRecorder, McapRecording
from cananalyze.formats.source import open_log, read_all
from cananalyze.pipeline import Decoder
from cananalyze.protocol.cobid import CobClassifier
from cananalyze.runtime import speedups

FIELDS = [name for name, _, _ in FRAME_FIELDS]
BITS = {
    "ext": FLAG_EXT,
    "rtr": FLAG_RTR,
    "err": FLAG_ERR,
    "fd": FLAG_FD,
    "brs": FLAG_BRS,
    "esi": FLAG_ESI,
    "tx": FLAG_TX,
}


def cli(*args: str, stdin: bytes | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, cwd=ROOT, input=stdin
    )


def mcap_frames(path: Path) -> list[dict]:
    """The /can/frames messages as the `mcap` package reads them, checked against the schema."""
    out = []
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for schema, channel, message in reader.iter_messages(topics=[FRAMES_TOPIC]):
            assert schema.name == "cananalyze.Frame" and schema.encoding == "jsonschema"
            assert json.loads(schema.data) == FRAME_SCHEMA
            assert channel.message_encoding == "json"
            assert message.publish_time == message.log_time
            doc = json.loads(message.data)
            assert list(doc) == FIELDS
            out.append({"ns": message.log_time, **doc})
    return out


def pycan_frames(path: Path) -> list[dict]:
    """The frames of a log as python-can reads them, in the MCAP fields' terms."""
    out = []
    for m in can.LogReader(str(path)):
        flags = sum(
            bit
            for bit, on in (
                (FLAG_EXT, m.is_extended_id),
                (FLAG_RTR, m.is_remote_frame),
                (FLAG_ERR, m.is_error_frame),
                (FLAG_FD, m.is_fd),
                (FLAG_BRS, m.bitrate_switch),
                (FLAG_ESI, m.error_state_indicator),
                (FLAG_TX, not m.is_rx),
            )
            if on
        )
        data = "" if m.is_remote_frame else bytes(m.data).hex()
        out.append(
            {
                "t": m.timestamp,
                "can_id": m.arbitration_id,
                "flags": flags,
                "dlc": m.dlc,
                "data": data,
            }
        )
    return out


def run(capture, *args: str) -> subprocess.CompletedProcess:
    """A command run in this process, as `cli` runs it in another (which costs a second)."""
    capture.readouterr()
    rc = main(list(args))
    out = capture.readouterr()
    return subprocess.CompletedProcess(args, rc, out.out, out.err)


# `decode --format jsonl` does not run without the compiled helper yet (bytecols.compact
# of zero parts, being fixed apart from this): the text output is compared in both
# modes, the JSONL records where they can be made
JSONL = speedups.C is not None


def frame_lines(proc: subprocess.CompletedProcess) -> list[str]:
    """The frame lines of `decode`'s text output (they start with the time; SDO
    transaction lines and those the end of the log completes do not)."""
    return [x for x in proc.stdout.decode().splitlines() if re.match(r" *-?\d+\.\d{6}  ", x)]


def untimed(proc: subprocess.CompletedProcess) -> list[str]:
    """`decode`'s text lines without their time column and SDO latencies."""
    assert proc.returncode == 0, proc.stderr.decode()
    lines = proc.stdout.decode().splitlines()
    return [re.sub(r", latency [0-9.]+ ms", "", x.split(None, 1)[1]) for x in lines]


def jsonl_frames(proc: subprocess.CompletedProcess) -> list[dict]:
    assert proc.returncode == 0, proc.stderr.decode()
    return [json.loads(x) for x in proc.stdout.decode().splitlines()]


def same_records(got: list[dict], want: list[dict], tol: float = 5e-10) -> None:
    """decode --format jsonl records equal; `t` to the ns an MCAP log time keeps."""
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        for key in ("t", "t_boot"):  # a frame's or record's time, a boot story's boot-up
            if key in w:
                assert g.pop(key) == pytest.approx(w[key], abs=tol, rel=0)
                w = {k: v for k, v in w.items() if k != key}
        assert g == w


def check_export(log: Path, tmp_path: Path, capture, pycan: bool = True) -> None:
    """export --mcap, then: the mcap package's reading of the file against python-can's
    of the log, and `decode x.mcap` against `decode LOG`."""
    out = tmp_path / "x.mcap"
    assert run(capture, "export", str(log), "--mcap", str(out), "-q").returncode == 0
    written = mcap_frames(out)
    original = read_all(log)
    assert len(written) == len(original) > 0
    assert [d["ns"] for d in written] == log_time_ns(original.t).tolist()
    assert [d["channel"] for d in written] == [
        original.channel_name(i) for i in range(len(original))
    ]
    if pycan:
        ref = pycan_frames(log)
        assert len(ref) == len(written)
        for w, r in zip(written, ref, strict=True):
            if w["flags"] & FLAG_ERR:  # python-can's candump reader sees an extended id
                continue
            assert {k: w[k] for k in ("can_id", "flags", "dlc", "data")} == {
                k: r[k] for k in ("can_id", "flags", "dlc", "data")
            }
            # python-can's ASC times are relative to the header's start: compare steps
            step_w = (w["ns"] - written[0]["ns"]) / 1e9
            assert step_w == pytest.approx(r["t"] - ref[0]["t"], abs=1e-6)
    text = run(capture, "decode", str(out))
    assert text.returncode == 0 and text.stdout == run(capture, "decode", str(log)).stdout
    if JSONL:
        same_records(
            jsonl_frames(run(capture, "decode", str(out), "--format", "jsonl")),
            jsonl_frames(run(capture, "decode", str(log), "--format", "jsonl")),
        )
    back = read_all(out)
    for column in ("can_id", "flags", "dlc", "data"):
        np.testing.assert_array_equal(getattr(back, column), getattr(original, column))
    assert back.long_data == original.long_data
    assert log_time_ns(back.t).tolist() == log_time_ns(original.t).tolist()


@pytest.mark.parametrize("name", ["demo.log", "demo.blf", "demo.asc", "faults.log"])
def test_export_then_decode_gives_the_samples_frames(name, tmp_path, capsysbinary):
    check_export(SAMPLES / name, tmp_path, capsysbinary)


@pytest.mark.parametrize(
    ("relative", "pycan"),
    [
        ("hilch__canopen-message-interpreter/pcan1.trc", True),  # PEAK TRC
        ("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log", True),
        ("collin80__SavvyCAN/candump.log", True),
        ("hardbyte__python-can/test_CanFdMessage64.asc", True),  # CAN FD, 64 bytes
        ("hardbyte__python-can/test_CanFdMessage.asc", True),  # FD with BRS/ESI, 3 channels
        ("hardbyte__python-can/test_CanErrorFrameExt.blf", False),  # error + extended
    ],
)
def test_export_then_decode_gives_real_logs_frames(relative, pycan, tmp_path, capsysbinary):
    check_export(real_file(relative), tmp_path, capsysbinary, pycan=pycan)


def test_decode_reads_an_mcap_from_stdin(tmp_path, capsysbinary):
    out = tmp_path / "x.mcap"
    assert (
        run(capsysbinary, "export", str(SAMPLES / "demo.log"), "--mcap", str(out), "-q").returncode
        == 0
    )
    piped = cli("decode", "-", stdin=out.read_bytes())
    assert piped.returncode == 0 and piped.stdout == run(capsysbinary, "decode", str(out)).stdout
    assert len(frame_lines(piped)) == 185


# --- every field value, both parsers ---------------------------------------------


def _frames(rows: list[tuple], channels: tuple[str, ...]) -> FrameBatch:
    """(t, can_id, flags, payload, channel, dlc or None) rows, dlc given for RTR frames."""
    b = FrameBatch.allocate(len(rows), channels)
    for i, (t, can_id, flags, payload, chan, dlc) in enumerate(rows):
        set_row(b, i, t, can_id, flags, payload, chan, i + 1)
        if dlc is not None:
            b.dlc[i] = dlc
    return b


def _write(path: Path, fb: FrameBatch, docs: Texts | None = None, chunk_bytes: int = 1 << 20):
    """fb as an export writes its /can/frames topic (or other documents in its place)."""
    c = CobClassifier().classify(fb)
    docs = frame_payloads(fb, c.service, c.node) if docs is None else docs
    with open(path, "wb") as f:
        w = BulkMcapWriter(f, "test", chunk_bytes=chunk_bytes)
        sid = w.schema("cananalyze.Frame", "jsonschema", json.dumps(FRAME_SCHEMA).encode())
        ch = w.channel(FRAMES_TOPIC, "json", sid)
        w.messages(np.full(len(fb), ch, np.uint16), log_time_ns(fb.t), docs)
        w.finish()


def _assert_same(got: FrameBatch, want: FrameBatch) -> None:
    assert len(got) == len(want)
    for column in ("can_id", "flags", "dlc", "data"):
        np.testing.assert_array_equal(getattr(got, column), getattr(want, column), column)
    assert got.long_data == want.long_data
    assert log_time_ns(got.t).tolist() == log_time_ns(want.t).tolist()
    assert [got.channel_name(i) for i in range(len(got))] == [
        want.channel_name(i) for i in range(len(want))
    ]


def _respaced(docs: Texts) -> Texts:
    """The same documents as json.dumps writes them by default (spaces after , and :)."""
    return Texts.from_list([json.dumps(json.loads(docs[i])).encode() for i in range(len(docs))])


frame_rows = st.lists(
    st.tuples(
        st.integers(0, 4 * 10**18).map(lambda ns: ns / 1e9),
        st.booleans(),  # extended
        st.integers(0, 0x1FFFFFFF),
        st.integers(0, 0x7F),  # flags
        st.binary(max_size=64),
        st.integers(0, 2),  # channel
    ),
    min_size=1,
    max_size=60,
)
channel_names = st.lists(
    st.text(min_size=1, max_size=40),
    min_size=3,
    max_size=3,
    unique=True,
)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(rows=frame_rows, names=channel_names)
def test_every_value_reads_back_through_both_parsers(rows, names, tmp_path):
    """Identifiers of 11 and 29 bits, all flag bits, 0-64 data bytes, RTR, any channel
    name (quotes, escapes, non-ASCII, longer than the template's 24 bytes): the frames
    come back exactly, from our documents (numpy template) and from the same documents
    spelt with spaces (pyarrow's JSON reader)."""
    table = []
    for t, ext, ident, flags, payload, chan in rows:
        flags = (flags & ~FLAG_EXT) | (FLAG_EXT if ext else 0)
        ident = ident if ext else ident & 0x7FF
        if flags & FLAG_RTR:
            table.append((t, ident, flags, b"", chan, len(payload)))
        else:
            table.append((t, ident, flags, payload, chan, None))
    fb = _frames(sorted(table, key=lambda row: row[0]), tuple(names))  # writers keep time order
    _write(tmp_path / "ours.mcap", fb)
    _assert_same(read_all(tmp_path / "ours.mcap"), fb)
    c = CobClassifier().classify(fb)
    _write(tmp_path / "spaced.mcap", fb, _respaced(frame_payloads(fb, c.service, c.node)))
    _assert_same(read_all(tmp_path / "spaced.mcap"), fb)


def test_template_and_json_reader_agree_on_a_generated_log(tmp_path, monkeypatch):
    """Thousands of ordinary frames: the numpy template parses all of them (the JSON
    reader none), and gives what the JSON reader gives."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from generate import generate

    fb = generate(20000)
    _write(tmp_path / "g.mcap", fb, chunk_bytes=1 << 16)
    generic = []
    real_generic = mcap_in._generic
    monkeypatch.setattr(
        mcap_in, "_generic", lambda *a: generic.append(len(a[3])) or real_generic(*a)
    )
    fast = read_all(tmp_path / "g.mcap")
    assert generic == []
    monkeypatch.setattr(mcap_in, "_template", lambda b, s, e, r, out, bad: np.zeros(len(s), bool))
    slow = read_all(tmp_path / "g.mcap")
    assert sum(generic) == len(fb)
    _assert_same(fast, fb)
    _assert_same(slow, fb)


@given(st.lists(st.text(alphabet="0123456789-+ .e", min_size=0, max_size=16), min_size=1))
@example(["0000000000000001", "1234567890123456", "99999999"])  # 16 digits: both words
def test_word_parsers_match_python(texts):
    """_swar.decimal and hex16 (8 bytes at a time) against int() and bytes.fromhex."""
    raw = b"".join(t.encode() + b"," for t in texts)
    buf = mcap_in._Buf(raw)
    at = np.cumsum([0] + [len(t) + 1 for t in texts[:-1]]).astype(np.int64)
    size = np.array([len(t) for t in texts], np.int64)
    words = [mcap_in._word(buf.rows(at, 3), 8 * j) for j in range(2)]
    value, ok = mcap_in._swar.decimal(words, size)
    for t, v, good in zip(texts, value.tolist(), ok.tolist(), strict=True):
        assert good == (t != "" and t.isdigit())
        if good:
            assert v == int(t)


@given(st.lists(st.text(alphabet="0123456789abcdefABCDEFgx ", max_size=16), min_size=1))
def test_hex_words_match_bytes_fromhex(texts):
    raw = b"".join(t.encode() + b'"' for t in texts)
    buf = mcap_in._Buf(raw)
    at = np.cumsum([0] + [len(t) + 1 for t in texts[:-1]]).astype(np.int64)
    size = np.array([len(t) for t in texts], np.int64)
    words = [mcap_in._word(buf.rows(at, 3), 8 * j) for j in range(2)]
    data, ok = mcap_in._swar.hex16(words, size)
    for i, t in enumerate(texts):
        try:
            want = bytes.fromhex(t) if " " not in t else None
        except ValueError:
            want = None
        assert bool(ok[i]) == (want is not None)
        if want is not None:
            assert data[i].tobytes() == want.ljust(8, b"\0")


@given(
    st.integers(0, 4102444800),  # whole seconds up to 2100
    st.integers(0, 999999),
    st.integers(0, 999999999),
)
def test_times_survive_the_ns_clock(sec, micro, nano):
    """A time parsed from a log's decimal (6 or 9 digits) comes back as the same float."""
    for text in (f"{sec}.{micro:06d}", f"{sec}.{nano:09d}", f"{sec % 100000}.{micro:06d}"):
        t = np.array([float(text)])
        assert seconds(log_time_ns(t))[0] == t[0]
        assert log_time_ns(t)[0] == round(Fraction(t[0]) * 10**9)  # the float's exact value


# --- older recordings ------------------------------------------------------------


def _write_legacy(path: Path, fb: FrameBatch) -> None:
    """A recording as FrameRecorder wrote it before the shared schema: mcap's own
    Writer, one json.dumps of the cananalyze.CanFrame fields per frame."""
    schema = {"type": "object", "title": "cananalyze.CanFrame", "properties": {}}
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="", library="cananalyze")
        sid = w.register_schema("cananalyze.CanFrame", "jsonschema", json.dumps(schema).encode())
        ch = w.register_channel(FRAMES_TOPIC, "json", sid)
        for i in range(len(fb)):
            fl = int(fb.flags[i])
            rec = {
                "timestamp": float(fb.t[i]),
                "channel": fb.channel_name(i),
                "id": int(fb.can_id[i]),
                **{
                    name: bool(fl & bit)
                    for name, bit in (
                        ("extended", FLAG_EXT),
                        ("remote", FLAG_RTR),
                        ("error", FLAG_ERR),
                        ("fd", FLAG_FD),
                        ("brs", FLAG_BRS),
                        ("esi", FLAG_ESI),
                        ("tx", FLAG_TX),
                    )
                },
                "dlc": int(fb.dlc[i]),
                "data": "" if fl & FLAG_RTR else fb.payload(i).hex(),
            }
            ns = int(round(fb.t[i] * 1e9))
            w.add_message(ch, log_time=ns, data=json.dumps(rec).encode(), publish_time=ns)
        w.finish()


def test_older_canframe_recordings_open(tmp_path, capsysbinary):
    fd = bytes(range(64))
    fb = concat(
        [
            read_all(SAMPLES / "demo.log"),
            _frames(
                [
                    (1767225700.5, 0x18FF1234, FLAG_EXT | FLAG_TX, b"\x01\x02", 1, None),
                    (1767225700.6, 0x123, FLAG_FD | FLAG_BRS | FLAG_ESI, fd, 1, None),
                    (1767225700.7, 0x701, FLAG_RTR, b"", 0, 1),
                    (1767225700.8, 0x004, FLAG_ERR, bytes(8), 0, None),
                ],
                ("can0", "can1"),
            ),
        ]
    )
    _write_legacy(tmp_path / "old.mcap", fb)
    got = read_all(tmp_path / "old.mcap")
    assert len(got) == len(fb)
    for column in ("can_id", "flags", "dlc", "data"):
        np.testing.assert_array_equal(getattr(got, column), getattr(fb, column), column)
    assert got.long_data == {len(fb) - 3: fd}
    assert np.abs(got.t - fb.t).max() < 1e-6  # the old writer rounded t * 1e9
    assert got.channels == ("can0", "can1")
    # `decode` of the old recording says what it says of the same frames as a candump log
    write_log(fb, tmp_path / "same.log")
    old = run(capsysbinary, "decode", str(tmp_path / "old.mcap"))
    assert untimed(old) == untimed(run(capsysbinary, "decode", str(tmp_path / "same.log")))
    if JSONL:
        same_records(
            jsonl_frames(
                run(capsysbinary, "decode", str(tmp_path / "old.mcap"), "--format", "jsonl")
            ),
            jsonl_frames(
                run(capsysbinary, "decode", str(tmp_path / "same.log"), "--format", "jsonl")
            ),
            tol=1e-6,
        )


# --- live recording ----------------------------------------------------------------


def _extra_messages() -> list[can.Message]:
    """Frames the demo log lacks: 29-bit, CAN FD with BRS and ESI, 64 bytes, an error frame."""
    return [
        can.Message(arbitration_id=0x18FF1234, is_extended_id=True, data=b"\x11\x22\x33"),
        can.Message(
            arbitration_id=0x123,
            is_extended_id=False,
            is_fd=True,
            bitrate_switch=True,
            error_state_indicator=True,
            data=bytes(range(64)),
        ),
        can.Message(arbitration_id=0x7E5, is_extended_id=False, is_fd=True, data=bytes(12)),
        can.Message(arbitration_id=0x004, is_error_frame=True, data=bytes(8)),
        can.Message(arbitration_id=0x705, is_remote_frame=True, dlc=1, is_extended_id=False),
    ]


def test_live_recording_on_a_virtual_bus(tmp_path, monkeypatch, capsysbinary):
    """The live loop (LiveSource batches into FrameRecorder, as `cananalyze live
    --record` runs it) on python-can's virtual bus: the recording, read by the mcap
    package, holds every frame with every field, in chunks; `decode` reads it back."""
    monkeypatch.setattr(McapRecording, "FLUSH_FRAMES", 40)  # several chunks from 190 frames
    channel = f"mcap-rec-{time.monotonic_ns()}"
    sent = list(to_messages(read_all(SAMPLES / "demo.log"))) + _extra_messages()
    rx = can.Bus(interface="virtual", channel=channel)
    source = LiveSource(rx, interval=0.01, batch_max=16)

    def pump():
        tx = can.Bus(interface="virtual", channel=channel)
        try:
            for k, msg in enumerate(sent):
                tx.send(msg)
                if k % 10 == 0:
                    time.sleep(0.002)
            # stopped once every frame is through (not after a fixed pause: a loaded
            # machine can keep the reader from the virtual bus's queue for longer)
            deadline = time.monotonic() + 60
            while sum(map(len, seen)) < len(sent) and time.monotonic() < deadline:
                time.sleep(0.01)
        finally:
            tx.shutdown()
            source.stop()

    rec_path = tmp_path / "live.mcap"
    recorder = FrameRecorder(rec_path)
    seen = []
    th = threading.Thread(target=pump)
    th.start()
    try:
        for fb in source.batches():
            if len(fb):
                recorder.write(fb)
                seen.append(fb)
    finally:
        th.join()
        source.close()
        recorder.close()
    live = concat(seen)
    assert recorder.frames == len(live) == len(sent) == 190

    with open(rec_path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert reader.get_header().library.startswith("cananalyze")
        # a chunk whenever 40 frames wait after a batch (or a second passed), and the rest
        # at close: as many as the batches as they came make, at least (a loaded machine
        # drains the virtual bus in fewer, larger batches than batch_max)
        waiting, flushes = 0, 0
        for fb in seen:
            waiting += len(fb)
            if waiting >= 40:
                flushes, waiting = flushes + 1, 0
        flushes += waiting > 0
        assert summary.statistics.message_count == 190
        assert len(summary.chunk_indexes) >= flushes  # 4 with batch_max-sized batches
        assert [c.topic for c in summary.channels.values()] == [FRAMES_TOPIC]
    written = mcap_frames(rec_path)
    assert [d["ns"] for d in written] == log_time_ns(live.t).tolist()
    assert all(d["channel"] == channel for d in written)
    for d, m in zip(written, sent, strict=True):
        flags = {name for name, bit in BITS.items() if d["flags"] & bit}
        want = {
            name
            for name, on in (
                ("ext", m.is_extended_id),
                ("rtr", m.is_remote_frame),
                ("err", m.is_error_frame),
                ("fd", m.is_fd),
                ("brs", m.bitrate_switch),
                ("esi", m.error_state_indicator),
            )
            if on
        }
        assert (d["can_id"], d["dlc"], flags) == (m.arbitration_id, m.dlc, want)
        assert d["data"] == ("" if m.is_remote_frame else bytes(m.data).hex())
    # the annotations are the predefined connection set's
    services = [d["service"] for d in written]
    assert services[:3] == ["bootup", "bootup", "bootup"] and services[-1] == "guard_request"

    # `decode` reads the recording as it reads the session's frames written as candump
    write_log(live, tmp_path / "live.log")
    decoded = run(capsysbinary, "decode", str(rec_path))
    assert len(frame_lines(decoded)) == 190
    assert untimed(decoded) == untimed(run(capsysbinary, "decode", str(tmp_path / "live.log")))
    if JSONL:
        back = jsonl_frames(run(capsysbinary, "decode", str(rec_path), "--format", "jsonl"))
        frames = [r for r in back if r["kind"] == "frame"]
        assert [(r["can_id"], r["data"], r["channel"]) for r in frames] == [
            (m.arbitration_id, "" if m.is_remote_frame else bytes(m.data).hex(), channel)
            for m in sent
        ]
        assert [r["t"] for r in frames] == pytest.approx(live.t.tolist(), abs=5e-10, rel=0)


def test_recorder_takes_decoded_batches_and_sorts_times(tmp_path):
    """Given the decoder's batch, the recording carries the decoder's services; frames
    from clocks that disagree are written in time order, none lost."""
    fb = read_all(SAMPLES / "demo.log")
    shuffled = fb.take(np.r_[10 : len(fb), 0:10])
    rec = FrameRecorder(tmp_path / "r.mcap")
    decoded = Decoder().decode(shuffled)
    rec.write(decoded)
    rec.close()
    rec.close()  # idempotent
    written = mcap_frames(tmp_path / "r.mcap")
    order = np.argsort(shuffled.t, kind="stable")
    assert [d["ns"] for d in written] == log_time_ns(shuffled.t[order]).tolist()
    from cananalyze.protocol.services import SERVICE_NAMES

    assert [d["service"] for d in written] == [SERVICE_NAMES[s] for s in decoded.service[order]]
    assert [d["node"] for d in written] == decoded.node[order].tolist()


# --- damaged and foreign files ------------------------------------------------------


def _recording(path: Path, frames: int = 3000, per_chunk: int = 500) -> FrameBatch:
    """A finished live recording of generated frames, a chunk per `per_chunk`."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from generate import generate

    fb = generate(frames)
    rec = McapRecording(path)
    for a in range(0, frames, per_chunk):
        rec.write(fb.take(slice(a, a + per_chunk)))
        rec.flush()
    rec.close()
    return fb


def test_mcap_without_the_frames_topic_is_one_line(tmp_path):
    bag = tmp_path / "bag.mcap"
    with open(bag, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema("sensor_msgs/Imu", "jsonschema", b"{}")
        chans = [w.register_channel(t, "json", sid) for t in ("/imu", "/tf")]
        for i in range(50):
            w.add_message(chans[i % 2], log_time=i, data=b"{}", publish_time=i)
        w.finish()
    out = cli("decode", str(bag))
    err = out.stderr.decode()
    assert out.returncode == 2 and b"Traceback" not in out.stderr
    assert err.strip() == (
        f"cananalyze: error: {bag}: an MCAP file without a /can/frames topic "
        "(its topics: /imu, /tf)"
    )
    # without its summary (cut at the end) the topics are found in the records
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bag.read_bytes()[:-40])
    out = cli("decode", str(cut))
    lines = out.stderr.decode().splitlines()
    assert out.returncode == 2 and b"Traceback" not in out.stderr
    assert lines[-1].endswith("an MCAP file without a /can/frames topic (its topics: /imu, /tf)")


def test_frames_topic_of_another_schema_is_one_line(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("foxglove.RawCan", "protobuf", b"")
        ch = w.register_channel(FRAMES_TOPIC, "protobuf", sid)
        w.add_message(ch, log_time=1, data=b"\x08\x01", publish_time=1)
        w.finish()
    out = cli("decode", str(path))
    assert out.returncode == 2 and b"Traceback" not in out.stderr
    err = out.stderr.decode().strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "'foxglove.RawCan'" in err[0]


def test_zip_files_still_say_zip(tmp_path):
    path = tmp_path / "x.zip"
    path.write_bytes(b"PK\x03\x04" + bytes(100))
    out = cli("decode", str(path))
    assert out.returncode == 2 and "looks like a ZIP file" in out.stderr.decode()


@pytest.mark.parametrize("keep", [0.45, 0.8, 0.97])
def test_cut_off_recording_keeps_its_frames(keep, tmp_path, capsysbinary):
    """A recording cut anywhere (a session killed, a copy interrupted): every frame of
    the complete chunks before the cut, one warning, no traceback; --strict the same
    frames and exit 2."""
    full = tmp_path / "full.mcap"
    fb = _recording(full)
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * keep)])
    with open(full, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    whole = sum(1 for c in chunks if c.chunk_start_offset + c.chunk_length <= int(len(data) * keep))
    src = open_log(cut)
    got = concat(list(src.batches()))
    assert len(got) == 500 * whole and (whole > 0 or keep < 0.5)
    _assert_same(got, fb.take(slice(0, len(got))))
    assert src.problems.count == 1
    assert "file ends" in src.problems.shown[0].message
    out = run(capsysbinary, "decode", str(cut))
    err = out.stderr.decode()
    assert out.returncode == 0 and f"{cut}:byte " in err and "cut off" in err
    assert len(frame_lines(out)) == len(got)
    strict = cli("decode", str(cut), "--strict")
    assert strict.returncode == 2 and b"Traceback" not in strict.stderr
    assert len(frame_lines(strict)) == len(got)


def test_recording_with_its_summary_cut_off_has_every_frame(tmp_path):
    """Cut inside the summary (after DataEnd): nothing is missing, nothing to report."""
    full = tmp_path / "full.mcap"
    fb = _recording(full)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[:-100])
    src = open_log(cut)
    _assert_same(concat(list(src.batches())), fb)
    assert src.problems.count == 0


def test_corrupt_chunk_is_skipped_with_a_problem(tmp_path):
    full = tmp_path / "full.mcap"
    fb = _recording(full)
    with open(full, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    third = chunks[2]
    data = bytearray(full.read_bytes())
    middle = third.chunk_start_offset + third.chunk_length // 2
    data[middle : middle + 8] = bytes(b ^ 0xFF for b in data[middle : middle + 8])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    src = open_log(bad)
    got = concat(list(src.batches()))
    assert len(got) == len(fb) - 500
    _assert_same(got, fb.take(np.r_[0:1000, 1500 : len(fb)]))
    assert got.line.tolist() == [*range(1, 1001), *range(1001, len(fb) - 499)]
    assert src.problems.count == 1
    problem = src.problems.shown[0]
    assert problem.location == "message 1001"
    assert f"chunk at byte {third.chunk_start_offset}" in problem.message
    strict = cli("decode", str(bad), "--strict")
    assert strict.returncode == 2 and b"Traceback" not in strict.stderr
    assert len(frame_lines(strict)) == 1000


def test_broken_documents_are_problems_of_their_message(tmp_path):
    good = {"channel": "can0", "can_id": 0x181, "dlc": 2, "data": "0102", "flags": 0}
    docs = [
        json.dumps(good, separators=(",", ":")).encode(),
        b"not json",
        json.dumps({**good, "can_id": 0x20000000}).encode(),
        json.dumps({**good, "data": "zz"}).encode(),
        json.dumps({**good, "flags": 300}).encode(),
        json.dumps({k: v for k, v in good.items() if k != "dlc"}).encode(),
        json.dumps({**good, "can_id": 0x182}, indent=2).encode(),  # line breaks: fine
        json.dumps({**good, "can_id": 0x183}).encode(),
    ]
    path = tmp_path / "docs.mcap"
    with open(path, "wb") as f:
        w = BulkMcapWriter(f, "test")
        sid = w.schema("cananalyze.Frame", "jsonschema", json.dumps(FRAME_SCHEMA).encode())
        ch = w.channel(FRAMES_TOPIC, "json", sid)
        ns = np.arange(len(docs), dtype=np.int64) * 1000 + 1_700_000_000 * 10**9
        w.messages(np.full(len(docs), ch, np.uint16), ns, Texts.from_list(docs))
        w.finish()
    src = open_log(path)
    got = concat(list(src.batches()))
    assert got.can_id.tolist() == [0x181, 0x182, 0x183]
    assert got.line.tolist() == [1, 7, 8]
    assert [p.location for p in src.problems.shown] == [f"message {i}" for i in (2, 3, 4, 5, 6)]
    messages = [p.message for p in src.problems.shown]
    assert "not a JSON document" in messages[0] and "out of range" in messages[1]
    assert "'zz'" in messages[2] and "flags 300" in messages[3] and "missing" in messages[4]
    strict = cli("decode", str(path), "--strict")
    assert strict.returncode == 2 and b"Traceback" not in strict.stderr
    assert f"{path}:message 2: not a JSON document".encode() in strict.stderr
    assert len(frame_lines(strict)) == 1


def test_forced_mcap_format_on_a_log_is_one_line(tmp_path):
    out = cli("decode", str(SAMPLES / "demo.log"), "--input-format", "mcap")
    assert out.returncode == 2 and b"Traceback" not in out.stderr
    assert "not an MCAP file" in out.stderr.decode()
    with pytest.raises(InputError):
        list(open_log(SAMPLES / "demo.log", fmt="mcap").batches())


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_other_chunk_compressions_read(compression, tmp_path, capsysbinary):
    out = tmp_path / "x.mcap"
    proc = run(
        capsysbinary, "export", str(SAMPLES / "demo.log"), "--mcap", str(out),
        "--mcap-compression", compression, "-q",
    )  # fmt: skip
    assert proc.returncode == 0
    with open(out, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert {c.compression for c in chunks} == {"" if compression == "none" else compression}
    _assert_same(read_all(out), read_all(SAMPLES / "demo.log"))


def test_messages_outside_chunks_read(tmp_path, monkeypatch):
    """An unchunked file (mcap's Writer without chunking): Message records at the top
    level, parsed a few kilobytes at a time."""
    monkeypatch.setattr(mcap_in, "LOOSE_BYTES", 2000)
    fb = read_all(SAMPLES / "faults.log")
    c = CobClassifier().classify(fb)
    docs = frame_payloads(fb, c.service, c.node)
    ns = log_time_ns(fb.t).tolist()
    path = tmp_path / "flat.mcap"
    with open(path, "wb") as f:
        w = Writer(f, use_chunking=False)
        w.start()
        sid = w.register_schema("cananalyze.Frame", "jsonschema", json.dumps(FRAME_SCHEMA).encode())
        ch = w.register_channel(FRAMES_TOPIC, "json", sid)
        for i in range(len(fb)):
            w.add_message(ch, log_time=ns[i], data=docs[i], publish_time=ns[i])
        w.finish()
    src = open_log(path, batch_size=100)
    batches = list(src.batches())
    assert len(batches) > 5 and max(len(b) for b in batches) == 100
    _assert_same(concat(batches), fb)
    assert src.problems.count == 0


@pytest.mark.parametrize("batch_size", [1, 7, 499, 1 << 18])
def test_batches_hold_batch_size_frames_whatever_the_chunks(batch_size, tmp_path):
    """Batches are cut at the batch size, not at chunk ends (500 frames a chunk here)."""
    fb = _recording(tmp_path / "r.mcap", frames=1200, per_chunk=500)
    batches = list(open_log(tmp_path / "r.mcap", batch_size=batch_size).batches())
    assert [len(b) for b in batches[:-1]] == [batch_size] * (len(batches) - 1)
    assert 0 < len(batches[-1]) <= batch_size
    whole = concat(batches)
    _assert_same(whole, fb)
    assert whole.line.tolist() == list(range(1, 1201))
