"""The bulk MCAP writer against the `mcap` package: same messages as its own Writer, valid
structure for indexed readers (chunk indexes, message indexes, statistics, summary offsets).

Oracle: a reference file written here with `mcap.writer.Writer.add_message`, one message at
a time, its payloads made with `json.dumps` from `load()`'s Capture of the same log; the
exported file is what `export --mcap` writes.
"""

from __future__ import annotations

import io
import json
import math
import struct
import sys
import zlib
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import zstandard
from conftest import SAMPLES
from exported import DEMO_DEVICES, DEVICES, decoded_batches, export
from hypothesis import given
from hypothesis import strategies as st
from mcap.data_stream import ReadDataStream
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import (
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    MessageIndex,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

import cananalyze
from cananalyze.core.frames import FLAG_RTR
from cananalyze.formats.mcap_frames import FRAME_SCHEMA
from cananalyze.outputs.capture import Capture
from cananalyze.outputs.mcap.stream import StreamMcap
from cananalyze.outputs.mcap.topics import LOG_SCHEMA, STATE_SCHEMA, signal_schema
from cananalyze.protocol.services import SERVICE_NAMES

DEMO = SAMPLES / "demo.log"


@pytest.fixture(scope="module")
def demo():
    return DEMO, DEMO_DEVICES


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from generate import generate

    from cananalyze.formats.logfile import write_log

    log = tmp_path_factory.mktemp("gen") / "g.log"
    write_log(generate(30000), log)
    return log, DEVICES


def _plain(v):
    v = v.item() if isinstance(v, np.generic) else v
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _frame_doc(cap: Capture, i: int) -> dict:
    fb = cap.batch
    data = (
        "" if fb.flags[i] & FLAG_RTR else fb.long_data.get(i, bytes(fb.data[i, : fb.dlc[i]])).hex()
    )
    return {
        "channel": fb.channels[fb.channel[i]],
        "can_id": int(fb.can_id[i]),
        "dlc": int(fb.dlc[i]),
        "data": data,
        "flags": int(fb.flags[i]),
        "service": SERVICE_NAMES[cap.service[i]],
        "node": int(cap.node[i]),
    }


def _event_doc(cap: Capture, e) -> dict:
    ns = round(Fraction(e.t) * 10**9)
    lines = cap.batch.line
    return {
        "timestamp": {"sec": ns // 10**9, "nsec": ns % 10**9},
        "level": e.level,
        "message": e.message,
        "name": f"node {e.node}" if e.node is not None else e.kind,
        "file": Path(str(cap.source)).name,
        "line": int(lines[e.row]) if e.row is not None and e.row < len(lines) else 0,
    }


def _reference_topics(cap: Capture) -> list[tuple[str, dict, list[int], list[bytes]]]:
    """(topic, schema, log times, payloads) of every topic, one json.dumps per message."""
    ns = lambda t: [round(Fraction(x) * 10**9) for x in np.asarray(t, np.float64).tolist()]  # noqa: E731
    out = []
    for s in cap.series:
        docs = [{k: _plain(v[i]) for k, v in s.columns.items()} for i in range(len(s.t))]
        out.append((f"/node/{s.node}/{s.pdo}", signal_schema(s), ns(s.t), docs))
    by_node: dict[int, list] = {}
    for e in cap.state_changes:
        by_node.setdefault(e.node, []).append(e)
    for node, evs in sorted(by_node.items()):
        docs = [{"state": e.message} for e in evs]
        out.append((f"/node/{node}/nmt_state", STATE_SCHEMA, ns([e.t for e in evs]), docs))
    events = cap.sorted_events()
    if events:
        docs = [_event_doc(cap, e) for e in events]
        out.append(("/canopen/events", LOG_SCHEMA, ns([e.t for e in events]), docs))
    if len(cap.batch):
        docs = [_frame_doc(cap, i) for i in range(len(cap.batch))]
        out.append(("/can/frames", FRAME_SCHEMA, ns(cap.batch.t), docs))
    return [(t, sc, times, [json.dumps(d).encode() for d in docs]) for t, sc, times, docs in out]


def _write_reference(cap: Capture, path: Path) -> None:
    """The same topics through mcap's own Writer, one add_message per message."""
    from mcap.writer import Writer

    streams = []
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=4 * 1024 * 1024)
        w.start(profile="", library="reference")
        for topic, schema, times, data in _reference_topics(cap):
            sid = w.register_schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            ch = w.register_channel(topic, "json", sid)
            streams += [(t, ch, d) for t, d in zip(times, data, strict=True)]
        for t, ch, d in sorted(streams, key=lambda s: s[0]):  # stable, like the exporter
            w.add_message(channel_id=ch, log_time=t, data=d, publish_time=t)
        w.finish()


def _messages(path: Path):
    with open(path, "rb") as f:
        return [
            (ch.topic, sc.name, m.log_time, m.publish_time, json.loads(m.data))
            for sc, ch, m in make_reader(f, validate_crcs=True).iter_messages()
        ]


def _stream_file(log: Path, devices, path: Path, compression="zstd", chunk_bytes=4 << 20):
    """The MCAP writer fed the decoded log directly, with a chunk size of its own."""
    with StreamMcap(path, compression, source=str(log), chunk_bytes=chunk_bytes) as s:
        for batch in decoded_batches(log, None, device=devices):
            s.add(batch)
        s.close()


def _by_topic(summary) -> dict:
    """Schema name, schema and message count of each topic (channel ids are the writer's)."""
    counts = summary.statistics.channel_message_counts
    return {
        c.topic: (
            summary.schemas[c.schema_id].name,
            json.loads(summary.schemas[c.schema_id].data),
            counts[c.id],
        )
        for c in summary.channels.values()
    }


@pytest.mark.parametrize("which", ["demo", "generated"])
@pytest.mark.slow
def test_same_messages_as_mcap_writer(which, request, tmp_path):
    log, devices = request.getfixturevalue(which)
    cap = cananalyze.load(log, device=devices)
    bulk_path = export(log, tmp_path, ("mcap",), device=devices)["mcap"]
    _write_reference(cap, tmp_path / "ref.mcap")
    bulk, ref = _messages(bulk_path), _messages(tmp_path / "ref.mcap")
    assert len(bulk) == len(ref) > len(cap)
    # the same messages; a transfer completed a batch later sits in a later chunk, so the
    # exporter's order is the reference's only per topic and within its time
    key = lambda m: (m[2], m[0], json.dumps(m[4], sort_keys=True))  # noqa: E731
    assert sorted(bulk, key=key) == sorted(ref, key=key)
    frames = [m for m in bulk if m[0] == "/can/frames"]
    assert frames == [m for m in ref if m[0] == "/can/frames"]
    with open(bulk_path, "rb") as f1, open(tmp_path / "ref.mcap", "rb") as f2:
        s1, s2 = make_reader(f1).get_summary(), make_reader(f2).get_summary()
    assert _by_topic(s1) == _by_topic(s2)
    st1, st2 = s1.statistics, s2.statistics
    assert st1.message_count == st2.message_count == len(bulk)
    assert (st1.message_start_time, st1.message_end_time) == (
        st2.message_start_time,
        st2.message_end_time,
    )
    assert (st1.schema_count, st1.channel_count) == (st2.schema_count, st2.channel_count)
    assert st1.chunk_count == len(s1.chunk_indexes)


_CLASSES = {
    0x03: Schema,
    0x04: Channel,
    0x06: Chunk,
    0x07: MessageIndex,
    0x08: ChunkIndex,
    0x0A: AttachmentIndex,
    0x0B: Statistics,
    0x0D: MetadataIndex,
    0x0E: SummaryOffset,
}
_GROUPS = {
    0x03: "Schema",
    0x04: "Channel",
    0x0B: "Statistics",
    0x08: "ChunkIndex",
    0x0A: "AttachmentIndex",
    0x0D: "MetadataIndex",
}


def _records(data: bytes) -> list:
    """Parse back-to-back records with the `mcap` package's record classes."""
    out, pos = [], 0
    while pos < len(data):
        op, ln = struct.unpack_from("<BQ", data, pos)
        body = ReadDataStream(io.BytesIO(data[pos + 9 : pos + 9 + ln]))
        out.append(_CLASSES[op].read(body))
        pos += 9 + ln
    return out


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_chunks_and_indexes_point_at_the_right_records(generated, tmp_path, compression):
    path = tmp_path / "g.mcap"
    _stream_file(*generated, path, compression, chunk_bytes=64 * 1024)
    raw = path.read_bytes()
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    chunks = summary.chunk_indexes
    assert len(chunks) == summary.statistics.chunk_count > 10
    n_msgs = 0
    last_end = -1
    for ci in chunks:
        assert isinstance(ci, ChunkIndex)
        assert raw[ci.chunk_start_offset] == 0x06
        (length,) = struct.unpack_from("<Q", raw, ci.chunk_start_offset + 1)
        assert ci.chunk_length == 9 + length
        (chunk,) = _records(raw[ci.chunk_start_offset : ci.chunk_start_offset + ci.chunk_length])
        assert isinstance(chunk, Chunk)
        assert chunk.compression == {"zstd": "zstd", "lz4": "lz4", "none": ""}[compression]
        assert len(chunk.data) == ci.compressed_size
        if compression == "zstd":
            body = zstandard.ZstdDecompressor().decompress(chunk.data, ci.uncompressed_size)
        elif compression == "lz4":
            import lz4.frame

            body = lz4.frame.decompress(chunk.data)
        else:
            body = chunk.data
        assert len(body) == ci.uncompressed_size == chunk.uncompressed_size
        assert zlib.crc32(body) == chunk.uncompressed_crc
        msgs = {}
        pos = 0
        while pos < len(body):  # the chunk holds Message records only, back to back
            op, ln = struct.unpack_from("<BQ", body, pos)
            assert op == 0x05
            ch, _seq, lt, pt = struct.unpack_from("<HIQQ", body, pos + 9)
            assert lt == pt
            msgs[pos] = (ch, lt)
            pos += 9 + ln
        assert pos == len(body)
        times = [lt for _, lt in msgs.values()]
        assert (min(times), max(times)) == (ci.message_start_time, ci.message_end_time)
        assert min(times) >= last_end  # chunks follow each other in time
        last_end = max(times)
        # one MessageIndex per channel right after the chunk, every message listed once
        assert ci.message_index_offsets
        listed = 0
        assert min(ci.message_index_offsets.values()) == ci.chunk_start_offset + ci.chunk_length
        for ch, off in ci.message_index_offsets.items():
            (mi,) = _records(raw[off : off + 9 + struct.unpack_from("<Q", raw, off + 1)[0]])
            assert isinstance(mi, MessageIndex) and mi.channel_id == ch
            for t, rel in mi.records:
                assert msgs[rel] == (ch, t)
            assert [t for t, _ in mi.records] == sorted(t for t, _ in mi.records)
            listed += len(mi.records)
        assert listed == len(msgs)
        end = max(ci.message_index_offsets.values())
        end += 9 + struct.unpack_from("<Q", raw, end + 1)[0]
        assert end - (ci.chunk_start_offset + ci.chunk_length) == ci.message_index_length
        n_msgs += len(msgs)
    assert n_msgs == summary.statistics.message_count
    # summary offsets name each group's opcode and span
    footer_at = len(raw) - 8 - 29
    assert raw[footer_at] == 0x02
    s_start, so_start, crc = struct.unpack_from("<QQI", raw, footer_at + 9)
    assert crc == zlib.crc32(raw[s_start : footer_at + 1 + 8 + 16])
    offsets = _records(raw[so_start:footer_at])
    assert {o.group_opcode for o in offsets} == {0x03, 0x04, 0x0B, 0x08, 0x0A, 0x0D}
    for o in offsets:
        assert raw[o.group_start] == o.group_opcode
        group = _records(raw[o.group_start : o.group_start + o.group_length])
        assert group and {type(r).__name__ for r in group} == {_GROUPS[o.group_opcode]}
    # the streaming reader (no summary, no seeking) sees the same messages
    with open(path, "rb") as f:
        streamed = [
            (c.topic, m.log_time, m.data) for _, c, m in NonSeekingReader(f).iter_messages()
        ]
    with open(path, "rb") as f:
        seeked = [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]
    assert streamed == seeked and len(seeked) == n_msgs
    assert all(isinstance(json.loads(d), dict) for _, _, d in seeked[:500])


def test_time_window_reads_use_chunk_indexes(generated, tmp_path):
    path = tmp_path / "g.mcap"
    _stream_file(*generated, path, chunk_bytes=32 * 1024)
    with open(path, "rb") as f:
        everything = [(c.topic, m.log_time) for _, c, m in make_reader(f).iter_messages()]
    t0, t1 = everything[len(everything) // 3][1], everything[2 * len(everything) // 3][1]
    with open(path, "rb") as f:
        window = [
            (c.topic, m.log_time)
            for _, c, m in make_reader(f).iter_messages(
                topics=["/can/frames"], starting_at=t0, ending_before=t1
            )
        ]
    expected = [e for e in everything if e[0] == "/can/frames" and t0 <= e[1] < t1]
    assert window == expected and len(expected) > 1000


def test_json_columns_fd_payloads_and_non_finite_values(tmp_path):
    from cananalyze.api.capture import load
    from cananalyze.core.columns.json_text import join, number_text, object_template
    from cananalyze.formats.mcap_frames import frame_payloads

    big = np.array([2**63 - 1, -(2**63), 0], np.int64)
    vals = np.array([0.1, np.nan, -np.inf])
    flags = np.array([True, False, True])
    doc = join(
        object_template(["i", "f", "b"], [number_text(big), number_text(vals), number_text(flags)])
    )
    got = [json.loads(doc[i]) for i in range(3)]
    assert got == [
        {"i": 2**63 - 1, "f": 0.1, "b": True},
        {"i": -(2**63), "f": None, "b": False},
        {"i": 0, "f": None, "b": True},
    ]
    log = tmp_path / "fd.log"
    payload = bytes(range(64))
    log.write_text(
        f"(1.000000) can0 181#0102\n(1.001000) can0 123##1{payload.hex()}\n(1.002000) can0 701#R\n"
    )
    c = load(log)
    docs = frame_payloads(c.batch, c.service, c.node)
    assert [json.loads(docs[i])["data"] for i in range(3)] == ["0102", payload.hex(), ""]
    assert json.loads(docs[1])["dlc"] == c.batch.dlc[1]


def test_payloads_built_in_slices_are_the_same(demo, tmp_path, monkeypatch):
    """Big logs are formatted a slice of rows at a time (pyarrow's 32-bit offsets)."""
    from cananalyze.formats import mcap_frames
    from cananalyze.outputs.mcap import topics as mcap_out

    log, devices = demo
    whole = export(log, tmp_path / "whole", ("mcap",), device=devices)["mcap"]
    monkeypatch.setattr(mcap_out, "SLICE", 7)
    monkeypatch.setattr(mcap_frames, "SLICE", 7)
    sliced = export(log, tmp_path / "sliced", ("mcap",), device=devices)["mcap"]
    whole, sliced = _messages(whole), _messages(sliced)
    assert sliced == whole and len(whole) > 3 * 7


def test_writer_on_its_own_empty_payloads_and_several_texts(tmp_path):
    from cananalyze.core.columns.json_text import Texts
    from cananalyze.formats.mcap_bulk import BulkMcapWriter

    a = Texts.from_list([b"", b"first", b""])
    b = Texts.from_list([b"second", b""])
    path = tmp_path / "w.mcap"
    with open(path, "wb") as f:
        w = BulkMcapWriter(f, "test", chunk_bytes=40)  # a chunk every message or two
        ch1 = w.channel("/a", "json", w.schema("s", "jsonschema", b"{}"))
        ch2 = w.channel("/b", "json", 0)
        rows = np.array([3, 0, 1, 4, 2])  # b0, a0, a1, b1, a2
        chans = np.array([ch2, ch1, ch1, ch2, ch1])
        w.messages(chans, np.array([5, 6, 6, 9, 10]), [a, b], rows=rows)
        with pytest.raises(ValueError, match="log-time order"):
            w.messages(np.array([ch1, ch1]), np.array([12, 11]), a, rows=np.array([0, 1]))
        w.messages(np.array([ch1]), np.array([12]), a, rows=np.array([1]))
        w.finish()
    with open(path, "rb") as f:
        r = make_reader(f, validate_crcs=True)
        got = [(c.topic, m.log_time, m.data) for _, c, m in r.iter_messages()]
        stats = r.get_summary().statistics
    assert got == [
        ("/b", 5, b"second"),
        ("/a", 6, b""),
        ("/a", 6, b"first"),
        ("/b", 9, b""),
        ("/a", 10, b""),
        ("/a", 12, b"first"),
    ]
    assert stats.message_count == 6 and stats.chunk_count > 2
    assert dict(stats.channel_message_counts) == {ch1: 4, ch2: 2}
    assert (stats.message_start_time, stats.message_end_time) == (5, 12)


@given(
    st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 40)), min_size=1, max_size=60),
    st.sampled_from([np.int32, np.int64]),
)
def test_ragged_ranges_match_repeat_and_arange(ranges, dtype):
    from cananalyze.formats.mcap_bulk import _ranges

    first = np.array([f for f, _ in ranges], np.int64)
    lengths = np.array([n for _, n in ranges], np.int64)
    before = np.cumsum(lengths) - lengths
    expected = np.concatenate([np.arange(f, f + n) for f, n in ranges])
    got = _ranges(first, lengths, before, np.empty(int(lengths.sum()), dtype))
    assert got.tolist() == expected.tolist()


@pytest.mark.parametrize("slice_rows", [1 << 20, 2])
def test_event_documents_are_json_dumps_of_the_dict(monkeypatch, slice_rows):
    """The /canopen/events documents are built as columns: byte for byte what json.dumps
    gives for the foxglove.Log dict, quotes, backslashes, control and non-ASCII text too."""
    from cananalyze.outputs.mcap import topics as mcap_out

    monkeypatch.setattr(mcap_out, "SLICE", slice_rows)
    msgs = ["plain", 'q"uote\\back', "ctl\x01\n\t", "ünï€😀", ""]
    ns = np.array([0, 1, 10**9, 1795000000123456789, 999999999], np.int64)
    levels, names, lines = (
        [1, 2, 3, 4, 5],
        ["node 5", "sdo", "node 127", 'x"y', "n"],
        [0, 1, 2, 3, 10**9],
    )
    got = mcap_out.event_payloads(ns, levels, msgs, names, 'a"b.log', lines)
    want = [
        json.dumps(
            {
                "timestamp": {"sec": int(t) // 10**9, "nsec": int(t) % 10**9},
                "level": lv,
                "message": m,
                "name": nm,
                "file": 'a"b.log',
                "line": ln,
            }
        ).encode()
        for t, lv, m, nm, ln in zip(ns, levels, msgs, names, lines, strict=True)
    ]
    assert [got[i] for i in range(len(got))] == want
    assert len(mcap_out.event_payloads(ns[:0], [], [], [], "f", [])) == 0
