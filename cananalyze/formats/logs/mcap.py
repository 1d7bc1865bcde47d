"""MCAP as an input: the `/can/frames` topic of an export or a live recording.

Reads messages of either frame schema (`cananalyze.Frame`, see
`formats/mcap_frames.py`, and the older live recordings' `cananalyze.CanFrame`)
from any MCAP file that has the topic, other topics skipped. Time is the message
log_time (absolute when after the year 2000, as for CSV logs); channel names are
kept; `line` is the message's number on the topic.

The `mcap` package parses the file's own records (schemas, channels, chunks, the
summary) and decompresses and CRC-checks chunks. Messages are not read one object
each: a chunk's Message records are found through its MessageIndex records (or,
without a summary, e.g. in a cut-off recording, by walking the record headers),
their fields gathered with numpy, and the JSON documents our writers produce are
cut apart column-wise (`_template`); other JSON spellings of the same fields go
through pyarrow's JSON reader, and only documents that fail there through
json.loads one by one.

Damage is reported, not raised: a file cut off keeps the frames before the cut, a
chunk that fails to decompress or its CRC is skipped; each is one problem.
"""

from __future__ import annotations

import io
import json
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

import numpy as np

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
    channel_index,
)
from cananalyze.formats.logs._rows import EPOCH_2000
from cananalyze.formats.mcap_frames import (
    FRAME_FIELDS,
    FRAME_SCHEMA_NAME,
    FRAMES_TOPIC,
    LEGACY_FRAME_SCHEMA_NAME,
    seconds,
)
from cananalyze.formats.registry import LogFormat, ReadContext, register

MAGIC = b"\x89MCAP0\r\n"
OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX = 0x03, 0x04, 0x05, 0x06, 0x07
OP_FOOTER, OP_DATA_END = 0x02, 0x0F
MESSAGE_HEAD = 31  # opcode, length, channel id, sequence, log time, publish time
MAX_CHUNK = 1 << 30  # uncompressed bytes one chunk may claim (writers use 1-8 MiB)
LOOSE_BYTES = 4 << 20  # Message records outside chunks gathered before they are parsed
FRAME, LEGACY = 1, 2  # schema kinds
MAX_FLAGS = 0xFF  # the eight FLAG_* bits
_RECORD = struct.Struct("<BQ")
_LEGACY_FLAGS = (
    ("extended", FLAG_EXT),
    ("remote", FLAG_RTR),
    ("error", FLAG_ERR),
    ("fd", FLAG_FD),
    ("brs", FLAG_BRS),
    ("esi", FLAG_ESI),
    ("tx", FLAG_TX),
)
_NIBBLE = np.full(256, 255, np.uint8)
_NIBBLE[np.frombuffer(b"0123456789abcdef", np.uint8)] = np.arange(16)
_NIBBLE[np.frombuffer(b"ABCDEF", np.uint8)] = np.arange(10, 16)


def sniff(head: bytes) -> bool:
    """MCAP files start with their magic (version 0)."""
    return head[:8] == MAGIC


@dataclass
class _Rows:
    """Parsed frames of one chunk, in file order (messages with a problem left out)."""

    number: np.ndarray  # message number on the topic (FrameBatch.line)
    log_time: np.ndarray  # int64 ns
    can_id: np.ndarray
    flags: np.ndarray
    dlc: np.ndarray
    data: np.ndarray  # (n, 8) uint8
    channel: np.ndarray  # index into the reader's channel table
    long: dict[int, bytes] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.number)

    def take(self, a: int, b: int) -> _Rows:
        long = {k - a: v for k, v in self.long.items() if a <= k < b}
        return _Rows(
            self.number[a:b],
            self.log_time[a:b],
            self.can_id[a:b],
            self.flags[a:b],
            self.dlc[a:b],
            self.data[a:b],
            self.channel[a:b],
            long,
        )


class _Reader:
    """One pass over the file's records in order; the summary, when there is one, is
    read first for the channels (and to skip chunks without frames)."""

    def __init__(self, stream: BinaryIO, ctx: ReadContext) -> None:
        self.stream = stream
        self.ctx = ctx
        self.src = ctx.source
        self.schemas: dict[int, tuple[str, str]] = {}  # id -> (name, encoding)
        self.topics: dict[int, str] = {}  # channel id -> topic (every channel seen)
        self.kinds: dict[int, int] = {}  # channel id -> FRAME / LEGACY, our topic only
        self.indexed = False  # a summary was read: its channels and the indexes hold
        self.chunk_channels: dict[int, set[int]] = {}  # chunk offset -> channels indexed in it
        self.number = 1  # the next message's number on the topic
        self.names: list[str] = []  # channel table of the batches
        self._name_index: dict[str, int] = {}
        self.size: int | None = None
        self.pos = 0
        self.chunk: tuple[int, bytes] | None = None  # (file offset, record body) read last
        self.index: dict[int, np.ndarray] = {}  # the chunk's message offsets per channel
        self.loose = bytearray()  # Message records outside chunks, in order
        self.ready: list[_Rows] = []
        self.waiting = 0

    # ------------------------------------------------------------------ file level
    def batches(self) -> Iterator[FrameBatch]:
        if self._read(8) != MAGIC:
            raise InputError(f"{self.src}: not an MCAP file (no MCAP magic at its start)")
        self.pos = 8
        self._summary()
        while True:
            head = self._read(9)
            if len(head) < 9:
                yield from self._end_chunk()
                what = "inside a record" if head else "without its summary and footer"
                self._problem(f"byte {self.pos}", f"file ends {what} (cut off?)")
                break
            op, length = _RECORD.unpack(head)
            if self.size is not None and self.pos + 9 + length > self.size:
                yield from self._end_chunk()
                self._problem(
                    f"byte {self.pos}",
                    f"file ends inside a record of {length} bytes (cut off or corrupt)",
                )
                break
            if op == OP_MESSAGE_INDEX and self.chunk is not None:
                if not self._message_index(length):
                    break
            else:
                yield from self._end_chunk()
                if op in (OP_DATA_END, OP_FOOTER):
                    break
                if not self._record(op, length):
                    break
                if len(self.loose) >= LOOSE_BYTES:  # an unchunked file: parse as it comes
                    yield from self._end_chunk()
            self.pos += 9 + length
        yield from self._flush(final=True)
        if not self.kinds:
            raise InputError(f"{self.src}: {self._no_topic()}")

    def _read(self, n: int) -> bytes:
        return self.stream.read(n)

    def _body(self, length: int) -> bytes | None:
        """The record's body, or None with a problem when the file ends inside it."""
        body = self._read(length)
        if len(body) < length:
            self._problem(f"byte {self.pos}", "file ends inside a record (cut off?)")
            return None
        return body

    def _skip(self, length: int) -> bool:
        if self.stream.seekable():
            self.stream.seek(length, io.SEEK_CUR)  # the size check above caught a cut
            return True
        while length > 0:
            got = len(self._read(min(length, 1 << 20)))
            if got == 0:
                self._problem(f"byte {self.pos}", "file ends inside a record (cut off?)")
                return False
            length -= got
        return True

    def _summary(self) -> None:
        """Channels and schemas from the summary, when the file has one: the topic is
        checked before any chunk is read, and chunks of other topics are skipped."""
        if not self.stream.seekable():
            return
        from mcap.reader import SeekingReader

        start = self.stream.tell()
        try:
            self.size = self.stream.seek(0, io.SEEK_END)
            self.stream.seek(0)
            summary = SeekingReader(self.stream).get_summary()
        except Exception:  # no usable summary (cut off, corrupt): read the file in order
            summary = None
        self.stream.seek(start)
        if summary is None or not summary.channels:
            return
        for s in summary.schemas.values():
            self.schemas[s.id] = (s.name, s.encoding)
        for c in summary.channels.values():
            self._channel(c.id, c.topic, c.message_encoding, c.schema_id)
        if not self.kinds:
            raise InputError(f"{self.src}: {self._no_topic()}")
        self.chunk_channels = {
            c.chunk_start_offset: set(c.message_index_offsets) for c in summary.chunk_indexes
        }
        self.indexed = True

    def _no_topic(self) -> str:
        topics = sorted(set(self.topics.values()))
        if not topics:
            return f"an MCAP file without a {FRAMES_TOPIC} topic (it has no topics)"
        shown = ", ".join(topics[:12]) + (
            f" and {len(topics) - 12} more" if len(topics) > 12 else ""
        )
        return f"an MCAP file without a {FRAMES_TOPIC} topic (its topics: {shown})"

    def _channel(self, cid: int, topic: str, encoding: str, schema_id: int) -> None:
        self.topics[cid] = topic
        if topic != FRAMES_TOPIC:
            return
        name, schema_encoding = self.schemas.get(schema_id, ("", ""))
        kind = {FRAME_SCHEMA_NAME: FRAME, LEGACY_FRAME_SCHEMA_NAME: LEGACY}.get(name)
        if kind is None or encoding != "json":
            shown = f"schema {name!r} ({schema_encoding})" if name else "no schema"
            raise InputError(
                f"{self.src}: its {FRAMES_TOPIC} topic has {shown} and {encoding} messages; "
                f"cananalyze reads {FRAME_SCHEMA_NAME} (or the older "
                f"{LEGACY_FRAME_SCHEMA_NAME}) JSON messages"
            )
        self.kinds[cid] = kind

    def _define(self, op: int, body: bytes | memoryview) -> None:
        """A Schema or Channel record (at the top level or inside a chunk)."""
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Schema

        stream = ReadDataStream(io.BytesIO(body))
        try:
            if op == OP_SCHEMA:
                s = Schema.read(stream)
                self.schemas[s.id] = (s.name, s.encoding)
            else:
                c = Channel.read(stream)
                if c.id not in self.topics:
                    self._channel(c.id, c.topic, c.message_encoding, c.schema_id)
        except InputError:
            raise
        except Exception as exc:  # a short or garbled record
            self._problem(f"byte {self.pos}", f"unreadable {_op_name(op)} record ({exc})")

    def _record(self, op: int, length: int) -> bool:
        """One top-level record other than a MessageIndex; False to stop reading."""
        if op == OP_CHUNK:
            listed = self.chunk_channels.get(self.pos)
            if self.indexed and listed and not listed & self.kinds.keys():
                return self._skip(length)  # the summary says: no frames in it
            body = self._body(length)
            if body is None:
                return False
            self.chunk = (self.pos, body)
            self.index = {}
            return True
        if op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
            body = self._body(length)
            if body is None:
                return False
            if op == OP_MESSAGE:
                self.loose += _RECORD.pack(op, length)
                self.loose += body
            else:
                self._define(op, body)
            return True
        return self._skip(length)  # header, attachments, metadata, indexes of skipped chunks

    def _message_index(self, length: int) -> bool:
        """A MessageIndex after the chunk just read: the offsets of our channel's messages."""
        if not self.indexed:
            return self._skip(length)  # without a summary the chunk is walked instead
        body = self._body(length)
        if body is None:
            return False
        if length >= 6:
            cid, size = struct.unpack_from("<HI", body)
            if cid in self.kinds and 6 + size <= length and size % 16 == 0:
                entries = np.frombuffer(body, "<u8", size // 8, 6).reshape(-1, 2)
                self.index[cid] = entries[:, 1].astype(np.int64)
        return True

    # ------------------------------------------------------------------ chunk level
    def _end_chunk(self) -> Iterator[FrameBatch]:
        """Parse the chunk read last (its MessageIndex records have followed it), and
        the Message records outside chunks read before it."""
        if self.loose:
            buf, self.loose = bytes(self.loose), bytearray()
            self._messages(buf, None, self.pos)
        if self.chunk is None:
            yield from self._flush(final=False)
            return
        offset, body = self.chunk
        index, self.chunk, self.index = self.index, None, {}
        buf = self._decompress(offset, body)
        if buf is None:
            return
        listed = self.chunk_channels.get(offset, set()) & self.kinds.keys()
        offsets = None  # walk the chunk's records, unless its indexes cover our channels
        if self.indexed and listed and listed <= index.keys():
            offsets = np.sort(np.concatenate([index[c] for c in listed]))
        self._messages(buf, offsets, offset)
        yield from self._flush(final=False)

    def _decompress(self, offset: int, body: bytes) -> bytes | None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Chunk
        from mcap.stream_reader import get_chunk_data_stream

        try:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
            if chunk.uncompressed_size > MAX_CHUNK:
                raise ValueError(f"it claims {chunk.uncompressed_size} bytes uncompressed")
            data, size = get_chunk_data_stream(chunk, validate_crc=True)
            buf = data.read(size)
            if len(buf) != chunk.uncompressed_size:
                raise ValueError(f"{len(buf)} bytes uncompressed, {chunk.uncompressed_size} said")
        except Exception as exc:  # zstandard, lz4, CRC and record errors have their own types
            self._problem(
                f"message {self.number}",
                f"chunk at byte {offset} cannot be read ({exc}); the frames in it are skipped",
            )
            return None
        return buf

    def _walk(self, buf: bytes, offset: int) -> np.ndarray:
        """Offsets of the Message records in a chunk, from its record headers (files
        without a summary); Schema and Channel records inside it are taken in."""
        found = []
        pos, n = 0, len(buf)
        unpack = _RECORD.unpack_from
        view = memoryview(buf)
        while pos + 9 <= n:
            op, length = unpack(buf, pos)
            end = pos + 9 + length
            if end > n:
                self._problem(
                    f"message {self.number + len(found)}",
                    f"chunk at byte {offset} is corrupt (a record runs past its end); "
                    "the rest of it is skipped",
                )
                break
            if op == OP_MESSAGE:
                found.append(pos)
            elif op in (OP_SCHEMA, OP_CHANNEL):
                self._define(op, view[pos + 9 : end])
            pos = end
        return np.array(found, np.int64)

    def _messages(self, raw: bytes, offsets: np.ndarray | None, at: int) -> None:
        """Our Message records in `raw` (a chunk's data, or loose records) as parsed rows."""
        buf = _Buf(raw)
        if offsets is not None and not _valid(buf, offsets, self.kinds):
            offsets = None  # an index that does not match the chunk: trust the records
        if offsets is None:
            offsets = self._walk(raw, at)
        if not len(offsets) or not self.kinds:
            return
        _, length, cid, log_time = _headers(buf, offsets)
        kind = _kinds(cid, self.kinds)
        ours = kind != 0
        offsets, length, kind, log_time = offsets[ours], length[ours], kind[ours], log_time[ours]
        n = len(offsets)
        if n == 0:
            return
        short = (length < MESSAGE_HEAD - 9) | (offsets + 9 + length > buf.n)
        number = self.number + np.arange(n, dtype=np.int64)
        self.number += n
        starts = offsets + MESSAGE_HEAD
        lengths = np.where(short, 0, length - (MESSAGE_HEAD - 9))
        rows = _Parsed(n)
        bad: dict[int, str] = {int(i): "message record too short" for i in np.flatnonzero(short)}
        for k in (FRAME, LEGACY):
            sel = np.flatnonzero((kind == k) & ~short)
            if len(sel):
                _parse(k, buf, starts[sel], lengths[sel], sel, rows, bad)
        keep = np.ones(n, bool)
        for i in sorted(bad):
            keep[i] = False
            self._problem(f"message {int(number[i])}", bad[i])
        channel = self._channel_table(rows.names, rows.channel)
        long = {}
        if rows.long:
            new = np.cumsum(keep) - 1
            long = {int(new[i]): v for i, v in rows.long.items() if keep[i]}
        out = _Rows(
            number[keep],
            log_time[keep],
            rows.can_id[keep].astype(np.uint32),
            rows.flags[keep].astype(np.uint8),
            rows.dlc[keep].astype(np.uint8),
            rows.data[keep],
            channel[keep],
            long,
        )
        if len(out):
            self.ready.append(out)
            self.waiting += len(out)

    def _channel_table(self, names: list[str], codes: np.ndarray) -> np.ndarray:
        table = [channel_index(self.names, self._name_index, name) for name in names]
        return np.asarray(table, np.uint16)[codes] if table else np.zeros(len(codes), np.uint16)

    def _flush(self, final: bool) -> Iterator[FrameBatch]:
        size = max(1, int(self.ctx.batch_size))
        while self.waiting >= size or (final and self.waiting):
            take, got = [], 0
            while got < size and self.ready:
                r = self.ready[0]
                if got + len(r) <= size:
                    take.append(self.ready.pop(0))
                    got += len(r)
                else:
                    cut = size - got
                    take.append(r.take(0, cut))
                    self.ready[0] = r.take(cut, len(r))
                    got = size
            self.waiting -= got
            yield self._batch(take)

    def _batch(self, parts: list[_Rows]) -> FrameBatch:
        t = seconds(np.concatenate([p.log_time for p in parts]))
        long: dict[int, bytes] = {}
        base = 0
        for p in parts:
            long.update({k + base: v for k, v in p.long.items()})
            base += len(p)
        batch = FrameBatch(
            t=t,
            can_id=np.concatenate([p.can_id for p in parts]),
            flags=np.concatenate([p.flags for p in parts]),
            dlc=np.concatenate([p.dlc for p in parts]),
            data=np.concatenate([p.data for p in parts]),
            channel=np.concatenate([p.channel for p in parts]),
            line=np.concatenate([p.number for p in parts]),
            channels=tuple(self.names),
            long_data=long,
        )
        if self.ctx.frames == 0 and len(t) and t[0] > EPOCH_2000:
            self.ctx.absolute_time = True
            self.ctx.start_time = float(t[0])
        self.ctx.frames += len(batch)
        return batch

    def _problem(self, location: str, message: str) -> None:
        self.ctx.problems.add(self.src, location, message)


def _op_name(op: int) -> str:
    return {OP_SCHEMA: "Schema", OP_CHANNEL: "Channel"}.get(op, f"opcode {op:#x}")


def _kinds(cid: np.ndarray, kinds: dict[int, int]) -> np.ndarray:
    """FRAME / LEGACY of each channel id, 0 for channels of other topics."""
    lut = np.zeros(0x10000, np.uint8)
    for c, k in kinds.items():
        lut[c] = k
    return lut[cid]


class _Buf:
    """A chunk's bytes, zero padded, and a view with a row of K little-endian u64
    words starting at every byte: one fancy index gathers a field's key and value
    bytes of every record at once (~12 ns a record, as fast as a single byte)."""

    PAD = 128  # more than the widest row (`rows`) reads past a document's start

    def __init__(self, raw: bytes) -> None:
        self.n = len(raw)
        self.b = np.zeros(self.n + self.PAD, np.uint8)
        self.b[: self.n] = np.frombuffer(raw, np.uint8)

    def rows(self, at: np.ndarray, k: int) -> np.ndarray:
        """(len(at), k) uint64: the 8 k bytes from each offset, as words."""
        view = np.ndarray((self.n + self.PAD - 8 * k + 1, k), "<u8", self.b, 0, (1, 8))
        return view[np.minimum(at, len(view) - 1)].astype(np.uint64, copy=False)


def _word(w: np.ndarray, byte: int) -> np.ndarray:
    """The 8 bytes from `byte` into each row of words (a constant offset: two shifts)."""
    q, r = divmod(byte, 8)
    if r == 0:
        return w[:, q]
    return (w[:, q] >> np.uint64(8 * r)) | (w[:, q + 1] << np.uint64(64 - 8 * r))


def _headers(buf: _Buf, offsets: np.ndarray):
    """Opcode, record length, channel id and log time of the records at the offsets."""
    w = buf.rows(offsets, 4)
    op = (w[:, 0] & np.uint64(0xFF)).astype(np.int64)
    length = _word(w, 1).astype(np.int64)
    cid = (_word(w, 9) & np.uint64(0xFFFF)).astype(np.int64)
    return op, length, cid, _word(w, 15).astype(np.int64)


def _valid(buf: _Buf, offsets: np.ndarray, kinds: dict[int, int]) -> bool:
    """Whether every index offset is a Message record of our channels inside the chunk."""
    if len(offsets) == 0:
        return True
    if offsets[0] < 0 or offsets[-1] + MESSAGE_HEAD > buf.n:
        return False
    op, length, cid, _ = _headers(buf, offsets)
    ends = offsets + 9 + length
    if (op != OP_MESSAGE).any() or (length < 0).any() or (ends > buf.n).any():
        return False
    if (ends[:-1] > offsets[1:]).any():
        return False
    return bool((_kinds(cid, kinds) != 0).all())


# ---------------------------------------------------------------------- documents
@dataclass
class _Parsed:
    """Columns of n documents being parsed; each parser fills its own rows."""

    n: int
    can_id: np.ndarray = field(init=False)
    flags: np.ndarray = field(init=False)
    dlc: np.ndarray = field(init=False)
    data: np.ndarray = field(init=False)
    channel: np.ndarray = field(init=False)  # index into names
    names: list[str] = field(default_factory=list)
    long: dict[int, bytes] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.can_id = np.zeros(self.n, np.int64)
        self.flags = np.zeros(self.n, np.int64)
        self.dlc = np.zeros(self.n, np.int64)
        self.data = np.zeros((self.n, 8), np.uint8)
        self.channel = np.zeros(self.n, np.int64)

    def name_codes(self, names: list[str]) -> np.ndarray:
        """Codes (into self.names) of a parser's own list of channel names."""
        index = {n: i for i, n in enumerate(self.names)}  # a batch's own list: no limit yet
        codes = []
        for name in names:
            if name not in index:
                index[name] = len(self.names)
                self.names.append(name)
            codes.append(index[name])
        return np.asarray(codes, np.int64)


def _parse(
    kind: int,
    buf: _Buf,
    starts: np.ndarray,
    lengths: np.ndarray,
    rows: np.ndarray,
    out: _Parsed,
    bad: dict[int, str],
) -> None:
    """Fill out's `rows` from the documents at buf[starts:starts + lengths]."""
    if kind == FRAME:
        done = _template(buf, starts, starts + lengths, rows, out, bad)
        rest = ~done
        starts, lengths, rows = starts[rest], lengths[rest], rows[rest]
        if not len(rows):
            return
    _generic(kind, buf.b, starts, lengths, rows, out, bad)


# bytes of each value the template reads; longer ones (CAN FD data, long channel
# names) are left to the JSON reader
_ROOM = {"channel": 24, "can_id": 10, "dlc": 2, "data": 16, "flags": 3}
_TEMPLATE_NEEDS = {"channel", "can_id", "dlc", "data", "flags"}


def _template(buf: _Buf, starts, ends, rows, out: _Parsed, bad) -> np.ndarray:
    """Documents exactly as `frame_payloads` writes them (FRAME_FIELDS in order, no
    spaces), cut apart 8 bytes at a time (`_swar`): per field one gather of its key
    and value, the key compared as words, the value's end found as the first byte
    equal to its closing quote or comma -- or, where it can be foretold, checked
    there: a channel named as in the first document, data of 2 * dlc hex digits.
    Returns which rows it parsed; the others go to `_generic`."""
    at = starts
    ok = np.ones(len(starts), bool)
    values, numbers = {}, {}
    for k, (name, kind, _) in enumerate(FRAME_FIELDS):
        if values.keys() >= _TEMPLATE_NEEDS:
            break
        key = ("{" if k == 0 else ",") + json.dumps(name) + ":" + ('"' if kind == "string" else "")
        room = _ROOM.get(name, 32)
        stop = '"' if kind == "string" else "}" if k == len(FRAME_FIELDS) - 1 else ","
        count = -(-(room + 1) // 8)  # value words the end is looked for in
        w = buf.rows(at, (len(key) + 8 * count) // 8 + 1)
        ok &= _swar.equals(w, key.encode())
        value = [_word(w, len(key) + 8 * j) for j in range(count)]
        size = np.full(len(at), -1, np.int64)  # -1: not foretold, look for the end
        if k == 0:
            size = _first_value(buf, starts[0], ends[0], key.encode(), w, room)
        elif name == "data" and "dlc" in numbers:
            guess = np.where(numbers["dlc"] <= 8, 2 * numbers["dlc"], -1)
            size = np.where(_swar.byte_at(value, guess) == ord(stop), guess, -1)
        look = size < 0
        if look.any():
            found = _swar.find(value, ord(stop), room + 1)
            if kind == "string":  # an escape inside would end the value early
                ok &= ~look | (_swar.find(value, ord("\\"), room) >= found)
            size = np.where(look, found, size)
        ok &= (size <= room) & (at + len(key) + size < ends)
        size = np.minimum(size, room)
        values[name] = (value, size, look)
        if name in ("can_id", "dlc", "flags"):
            numbers[name], good = _swar.decimal(value, size)
            ok &= good
        at = at + len(key) + size + (kind == "string")
    if not ok.any():
        return ok
    sel = np.flatnonzero(ok)
    r = rows[sel]
    for name, number in numbers.items():
        getattr(out, name)[r] = number[sel]
    value, size, look = values["channel"]
    if look[sel].any():
        out.channel[r] = _names([v[sel] for v in value], size[sel], out)
    else:  # all named as the first document
        out.channel[r] = _names([v[sel[:1]] for v in value], size[sel[:1]], out)[0]
    value, size, _ = values["data"]
    data, good = _swar.hex16([v[sel] for v in value], size[sel])
    out.data[r] = data
    ok[sel[~good]] = False
    _check(r[ok[sel]], out, bad)
    return ok


def _first_value(buf: _Buf, start: int, end: int, key: bytes, w: np.ndarray, room: int):
    """The first field's value size for rows whose key and value are the first
    document's (-1 for the others): one comparison instead of looking for its end."""
    none = np.full(len(w), -1, np.int64)
    doc = buf.b[start:end].tobytes()
    stop = doc.find(b'"', len(key))
    if not doc.startswith(key) or not 0 <= stop - len(key) <= room or b"\\" in doc[:stop]:
        return none
    prefix = doc[: stop + 1]
    if len(prefix) > 8 * w.shape[1]:
        return none
    return np.where(_swar.equals(w, prefix), stop - len(key), -1)


class _swar:
    """Byte tests on 8 bytes at once (SIMD within a register, on numpy u64 columns):
    no lane carries into another, so each answer is exact per byte."""

    ONES = np.uint64(0x0101010101010101)
    HIGH = np.uint64(0x8080808080808080)
    LOW7 = np.uint64(0x7F7F7F7F7F7F7F7F)
    LOW_BYTES = np.array([(1 << (8 * k)) - 1 for k in range(9)], np.uint64)  # k low bytes

    @classmethod
    def low(cls, n) -> np.ndarray:
        """Masks of the first n byte lanes (n clipped to 0..8)."""
        return cls.LOW_BYTES[np.clip(n, 0, 8)]

    @classmethod
    def nonzero(cls, w: np.ndarray) -> np.ndarray:
        """0x80 in each lane whose byte is not 0."""
        return (((w & cls.LOW7) + cls.LOW7) | w) & cls.HIGH

    @classmethod
    def between(cls, w: np.ndarray, lo: int, hi: int) -> np.ndarray:
        """0x80 in each lane whose byte is in lo..hi (1 <= lo <= hi < 0x80)."""
        low = w & cls.LOW7
        ge = low + np.uint64((0x80 - lo) * 0x0101010101010101)
        gt = low + np.uint64((0x7F - hi) * 0x0101010101010101)
        return ~w & ge & ~gt & cls.HIGH

    @classmethod
    def first(cls, m: np.ndarray) -> np.ndarray:
        """Index of the lowest lane flagged in m (8 when none)."""
        low = (m & (~m + np.uint64(1))) >> np.uint64(7)  # 1 << 8 * lane
        # the product's top byte is byte 7 - lane of the constant, which holds lane
        lane = (low * np.uint64(0x0001020304050607)) >> np.uint64(56)
        return np.where(m == 0, 8, lane.astype(np.int64))

    @classmethod
    def equals(cls, w: np.ndarray, text: bytes) -> np.ndarray:
        """Whether each row of words starts with text."""
        ok = np.ones(len(w), bool)
        for j in range(0, len(text), 8):
            part = text[j : j + 8]
            ok &= (w[:, j // 8] & cls.LOW_BYTES[len(part)]) == np.uint64(
                int.from_bytes(part, "little")
            )
        return ok

    @classmethod
    def byte_at(cls, words: list[np.ndarray], at: np.ndarray) -> np.ndarray:
        """The byte at offset `at` of each row's words (-1 where `at` is outside them)."""
        inside = (at >= 0) & (at < 8 * len(words))
        pos = np.where(inside, at, 0)
        stack = np.stack(words, axis=1)
        word = np.take_along_axis(stack, (pos // 8)[:, None], axis=1)[:, 0]
        byte = (word >> ((pos % 8) * 8).astype(np.uint64)) & np.uint64(0xFF)
        return np.where(inside, byte.astype(np.int64), -1)

    @classmethod
    def find(cls, words: list[np.ndarray], byte: int, room: int) -> np.ndarray:
        """Offset of the first `byte` in the first `room` bytes of the words (room if none)."""
        size = np.full(len(words[0]), room, np.int64)
        pattern = np.uint64(byte * 0x0101010101010101)
        for j in reversed(range(0, room, 8)):
            hit = ~cls.nonzero(words[j // 8] ^ pattern) & cls.low(room - j) & cls.HIGH
            lane = cls.first(hit)
            size = np.where(lane < 8, j + lane, size)
        return size

    @classmethod
    def digits8(cls, w: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The decimal in the first n (0..8) bytes of each word, and whether all are digits."""
        live = cls.low(n) & cls.HIGH
        ok = (cls.between(w, 0x30, 0x39) & live) == live
        shift = (np.uint64(8) - np.clip(n, 0, 8).astype(np.uint64)) * np.uint64(8)
        v = (w & cls.low(n)) << np.minimum(shift, np.uint64(56))
        v = np.where(n > 0, v, np.uint64(0))
        # eight ASCII digits (leading ones zero) to their value: pairs, quads, all eight
        v = ((v & np.uint64(0x0F0F0F0F0F0F0F0F)) * np.uint64(2561)) >> np.uint64(8)
        v = ((v & np.uint64(0x00FF00FF00FF00FF)) * np.uint64(6553601)) >> np.uint64(16)
        v = ((v & np.uint64(0x0000FFFF0000FFFF)) * np.uint64(42949672960001)) >> np.uint64(32)
        return v.astype(np.int64), ok

    @classmethod
    def decimal(cls, words: list[np.ndarray], size: np.ndarray):
        """Unsigned decimals of 1..16 digits at the start of the words, and which parsed."""
        low_n = np.minimum(size, 8)
        high_n = size - low_n
        if not high_n.any():  # no number over 8 digits (11-bit identifiers, dlc, flags)
            low, ok = cls.digits8(words[0], low_n)
            return low, ok & (size >= 1)
        high, ok_high = cls.digits8(words[0], high_n)
        h = np.clip(high_n, 1, 7).astype(np.uint64) * np.uint64(8)
        second = words[1] if len(words) > 1 else np.zeros_like(words[0])  # short fields
        shifted = (words[0] >> h) | (second << (np.uint64(64) - h))
        shifted = np.where(high_n >= 8, second, shifted)  # 16 digits: the low 8 are word 1
        low, ok_low = cls.digits8(np.where(high_n == 0, words[0], shifted), low_n)
        return high * 10**low_n + low, ok_high & ok_low & (size >= 1)

    @classmethod
    def hex16(cls, words: list[np.ndarray], size: np.ndarray):
        """(n, 8) bytes from up to 16 hex digits at the start of the words, and which parsed."""
        out = np.zeros(len(size), np.uint64)
        ok = size % 2 == 0
        for j, w in ((0, words[0]), (8, words[1])):
            live = cls.low(size - j) & cls.HIGH
            digit = cls.between(w, 0x30, 0x39) | cls.between(w, 0x61, 0x66)
            ok &= ((digit | cls.between(w, 0x41, 0x46)) & live) == live
            # '0'-'9' are 0x3N; 'a'-'f' and 'A'-'F' (0x6N, 0x4N) have bit 6 set: N + 9
            nib = (w & np.uint64(0x0F0F0F0F0F0F0F0F)) + np.uint64(9) * (
                (w >> np.uint64(6)) & cls.ONES
            )
            nib &= cls.low(size - j)
            # two nibbles to a byte in each 16-bit lane, then the four bytes side by side
            pairs = ((nib & np.uint64(0x00FF00FF00FF00FF)) << np.uint64(4)) | (
                (nib >> np.uint64(8)) & np.uint64(0x00FF00FF00FF00FF)
            )
            pairs = (pairs | (pairs >> np.uint64(8))) & np.uint64(0x0000FFFF0000FFFF)
            pairs = (pairs | (pairs >> np.uint64(16))) & np.uint64(0xFFFFFFFF)
            out |= pairs << np.uint64(4 * j)
        return out.view(np.uint8).reshape(len(size), 8), ok


def _names(words: list[np.ndarray], size: np.ndarray, out: _Parsed) -> np.ndarray:
    """Channel codes of the names in the first `size` bytes (up to 24) of the words."""
    key = np.empty((len(size), 4), np.uint64)
    for j in range(3):
        key[:, j] = words[j] & _swar.low(size - 8 * j)
    key[:, 3] = size
    if (key == key[0]).all():
        uniq, inverse = key[:1], np.zeros(len(key), np.int64)
    else:
        uniq, inverse = np.unique(key, axis=0, return_inverse=True)
    names = [
        row[:3].astype("<u8").tobytes()[: int(row[3])].decode("utf-8", "replace") for row in uniq
    ]
    return out.name_codes(names)[inverse.reshape(-1)]


def _hex_into(text: np.ndarray, size: np.ndarray, rows, out: _Parsed, bad) -> bool:
    """Payload bytes from up to 16 hex digits per row into out.data; bad rows noted."""
    inside = np.arange(16) < size[:, None]
    nib = _NIBBLE[text[:, :16]]
    ok = (size % 2 == 0) & ~((nib == 255) & inside).any(axis=1)
    nib[~inside] = 0
    out.data[rows] = (nib[:, 0::2] << 4) | nib[:, 1::2]
    for i in np.flatnonzero(~ok).tolist():
        shown = text[i, : min(int(size[i]), 16)].tobytes().decode("latin-1")
        bad.setdefault(int(rows[i]), f"data {shown!r} is not hex bytes")
    return ok


def _fill_data(chars: np.ndarray, at, size, rows, out: _Parsed, bad) -> None:
    """Payload bytes from hex text chars[at:at + size] into out.data (and out.long)."""
    padded = np.zeros(len(chars) + 16, np.uint8)
    padded[: len(chars)] = chars
    text = padded[at[:, None] + np.arange(16)]
    short = np.minimum(size, 16)
    _hex_into(text, short, rows, out, bad)
    for i in np.flatnonzero(size > 16).tolist():
        r = int(rows[i])
        raw = chars[at[i] : at[i] + size[i]].tobytes()
        try:
            payload = bytes.fromhex(raw.decode("latin-1"))
            if len(raw) % 2 or len(payload) > 64:
                raise ValueError
        except ValueError:
            bad.setdefault(
                r, f"data {raw[:40].decode('latin-1')!r}... is not the hex of up to 64 bytes"
            )
            continue
        out.long[r] = payload


def _check(rows: np.ndarray, out: _Parsed, bad: dict[int, str]) -> None:
    """Values no CAN frame has become problems of their message."""
    can_id, dlc, flags = out.can_id[rows], out.dlc[rows], out.flags[rows]
    wrong = (can_id < 0) | (can_id > 0x1FFFFFFF) | (dlc < 0) | (dlc > 64) | (flags < 0)
    wrong |= flags > MAX_FLAGS
    for i in np.flatnonzero(wrong).tolist():
        r = int(rows[i])
        if r in bad:
            continue
        if not 0 <= can_id[i] <= 0x1FFFFFFF:
            bad[r] = f"identifier {int(can_id[i]):#x} out of range"
        elif not 0 <= dlc[i] <= 64:
            bad[r] = f"dlc {int(dlc[i])} is more than a CAN frame carries"
        else:
            bad[r] = f"flags {int(flags[i])} has bits no CAN frame has (known: 0-{MAX_FLAGS})"


def _generic(kind, b, starts, lengths, rows, out: _Parsed, bad) -> None:
    """Documents in any JSON spelling: pyarrow's JSON reader over them all, or, when
    that refuses them, json.loads one by one to find the bad ones."""
    ndjson = _ndjson(b, starts, lengths)
    try:
        columns = _arrow_columns(kind, ndjson, len(rows))
    except ValueError:
        columns = _python_columns(kind, b, starts, lengths, rows, bad)
    names, codes, can_id, dlc, flags, hex_chars, hex_at, hex_len, missing = columns
    out.channel[rows] = out.name_codes(names)[codes] if names else 0
    out.can_id[rows], out.dlc[rows], out.flags[rows] = can_id, dlc, flags
    for i in np.flatnonzero(missing).tolist():
        bad.setdefault(int(rows[i]), "a frame field is missing or not of its type")
    _fill_data(hex_chars, hex_at, hex_len, rows, out, bad)
    _check(rows, out, bad)


def _ndjson(b: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> bytes:
    """The documents one per line (line breaks inside one are JSON whitespace: spaces)."""
    mark = np.zeros(len(b) + 1, np.int8)
    mark[starts - 1] = 1  # the byte before each document (a record header's) starts its line
    np.subtract.at(mark, starts + lengths, 1)
    inside = np.cumsum(mark[:-1]) > 0
    text = b.copy()
    text[inside & ((text == 10) | (text == 13))] = 32
    text[starts - 1] = 10
    return text[inside].tobytes()


def _arrow_columns(kind: int, ndjson: bytes, n: int):
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.json as pj

    from cananalyze.core.columns.json_text import Texts

    fields = [("channel", pa.string()), ("dlc", pa.int64()), ("data", pa.string())]
    if kind == FRAME:
        fields += [("can_id", pa.int64()), ("flags", pa.int64())]
    else:
        fields += [("id", pa.int64())] + [(name, pa.bool_()) for name, _ in _LEGACY_FLAGS]
    try:
        table = pj.read_json(
            io.BytesIO(ndjson),
            read_options=pj.ReadOptions(block_size=max(1 << 20, len(ndjson) + 1)),
            parse_options=pj.ParseOptions(
                explicit_schema=pa.schema(fields), unexpected_field_behavior="ignore"
            ),
        )
    except (pa.ArrowInvalid, pa.ArrowTypeError) as exc:
        raise ValueError(str(exc)) from None
    if table.num_rows != n:
        raise ValueError("not one JSON object per message")
    cols = {name: table.column(name).combine_chunks() for name, _ in fields}
    missing = np.zeros(n, bool)
    for name in ("channel", "dlc", "data", "can_id" if kind == FRAME else "id"):
        missing |= cols[name].is_null().to_numpy(zero_copy_only=False)

    def ints(name: str) -> np.ndarray:
        return pc.fill_null(cols[name], 0).to_numpy(zero_copy_only=False).astype(np.int64)

    if kind == FRAME:
        can_id, flags = ints("can_id"), ints("flags")
        missing |= cols["flags"].is_null().to_numpy(zero_copy_only=False)
    else:
        can_id, flags = ints("id"), np.zeros(n, np.int64)
        for name, bit in _LEGACY_FLAGS:
            flags |= pc.fill_null(cols[name], False).to_numpy(zero_copy_only=False) * bit
    channel = pc.fill_null(cols["channel"], "").dictionary_encode()
    names = channel.dictionary.to_pylist()
    codes = channel.indices.to_numpy(zero_copy_only=False).astype(np.int64)
    text = Texts.from_arrow(pc.fill_null(cols["data"], ""))
    return (
        names,
        codes,
        can_id,
        ints("dlc"),
        flags,
        text.data,
        text.offsets[:-1],
        text.lengths,
        missing,
    )


def _python_columns(kind, b, starts, lengths, rows, bad):
    """json.loads per document: only for documents pyarrow refused (some are broken)."""
    n = len(rows)
    names: list[str] = []
    codes = np.zeros(n, np.int64)
    can_id, dlc, flags = (np.zeros(n, np.int64) for _ in range(3))
    missing = np.zeros(n, bool)
    texts: list[bytes] = []
    id_key = "can_id" if kind == FRAME else "id"
    for i in range(n):
        raw = b[starts[i] : starts[i] + lengths[i]].tobytes()
        texts.append(b"")
        try:
            doc = json.loads(raw)
        except ValueError as exc:
            bad[int(rows[i])] = f"not a JSON document ({exc})"
            continue
        if not isinstance(doc, dict):
            bad[int(rows[i])] = "not a JSON object"
            continue
        chan, ident, size, data = (doc.get(k) for k in ("channel", id_key, "dlc", "data"))
        if kind == FRAME:
            bits = doc.get("flags")
        else:
            bits = sum(bit for name, bit in _LEGACY_FLAGS if doc.get(name) is True)
        if not (
            isinstance(chan, str)
            and isinstance(data, str)
            and all(type(v) is int for v in (ident, size, bits))
        ):
            missing[i] = True
            continue
        if chan not in names:
            names.append(chan)
        codes[i] = names.index(chan)
        can_id[i], dlc[i], flags[i] = ident, size, bits
        texts[i] = data.encode("latin-1", "replace")
    lens = np.array([len(t) for t in texts], np.int64)
    at = np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64)
    chars = np.frombuffer(b"".join(texts) or b"\0", np.uint8)
    return names, codes, can_id, dlc, flags, chars, at, lens, missing


def read(stream: BinaryIO, ctx: ReadContext) -> Iterator[FrameBatch]:
    """The /can/frames messages as FrameBatches of ctx.batch_size frames."""
    ctx.format = "mcap"
    yield from _Reader(stream, ctx).batches()


FORMAT = register(
    LogFormat(
        name="mcap",
        description="MCAP /can/frames topic (cananalyze export or live recording)",
        sniff=sniff,
        read=read,
        suffixes=(".mcap",),
        priority=10,
        text=False,
    )
)
