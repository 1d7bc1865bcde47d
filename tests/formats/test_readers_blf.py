"""Vector BLF reader against python-can's BLFReader on real fixtures and on written files."""

from __future__ import annotations

import random
import struct
import zlib
from types import SimpleNamespace

import can
import pytest
from conftest import real_file
from readers_util import assert_same_as_python_can, run

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_ERR, FLAG_FD
from cananalyze.formats.logs import blf

FIXTURES = [
    "test_CanMessage.blf",
    "test_CanMessage2.blf",
    "test_CanFdMessage.blf",
    "test_CanFdMessage64.blf",
    "test_CanErrorFrameExt.blf",
    "issue_1905.blf",
]


@pytest.mark.parametrize("name", FIXTURES)
def test_same_rows_as_python_can(name):
    path = real_file(f"hardbyte__python-can/{name}")
    batch, ctx, _ = run(blf.read, path, batch_size=5)
    expected = list(can.BLFReader(str(path)))
    assert len(batch) > 0
    assert_same_as_python_can(batch, expected)
    assert ctx.problems.count == 0 and ctx.format == "blf"


def test_fd_and_error_records():
    fd, _, _ = run(blf.read, real_file("hardbyte__python-can/test_CanFdMessage64.blf"))
    assert fd.flags[0] & FLAG_FD and len(fd.payload(0)) == 64
    err, _, _ = run(blf.read, real_file("hardbyte__python-can/test_CanErrorFrameExt.blf"))
    assert all(f & FLAG_ERR for f in err.flags)
    padded, ctx, _ = run(blf.read, real_file("hardbyte__python-can/issue_1905.blf"))
    assert ctx.absolute_time and ctx.start_time == pytest.approx(1735654180.222)


def _messages(n: int) -> list[can.Message]:
    rnd = random.Random(7)
    out = []
    for i in range(n):
        ext = rnd.random() < 0.2
        out.append(
            can.Message(
                timestamp=1700000000.0 + i * 0.0007,
                arbitration_id=rnd.randrange(0x20000000 if ext else 0x800),
                is_extended_id=ext,
                is_remote_frame=i % 97 == 0,
                data=b""
                if i % 97 == 0
                else bytes(rnd.randrange(256) for _ in range(rnd.randrange(9))),
                channel=rnd.randrange(3),
                is_rx=i % 5 != 0,
            )
        )
    return out


@pytest.fixture(scope="module", params=[0, 6], ids=["plain", "zlib"])
def written(request, tmp_path_factory):
    path = tmp_path_factory.mktemp("blf") / f"w{request.param}.blf"
    with can.BLFWriter(str(path), compression_level=request.param) as w:
        for m in _messages(12000):  # several 128 KiB containers, records straddle them
            w.on_message_received(m)
    return path


def test_written_files_match_python_can(written):
    batch, ctx, batches = run(blf.read, written, batch_size=5000)
    expected = list(can.BLFReader(str(written)))
    assert len(expected) == 12000
    assert [len(b) for b in batches] == [5000, 5000, 2000]
    assert_same_as_python_can(batch, expected)
    assert batch.line.tolist() == list(range(1, 12001))
    assert ctx.problems.count == 0 and ctx.frames == 12000


def test_file_cut_inside_a_container_reads_what_is_complete(written):
    data = written.read_bytes()
    cut = data[: len(data) * 2 // 3]
    batch, ctx, _ = run(blf.read, cut, source="cut.blf")
    expected = list(can.BLFReader(str(written)))
    assert 4000 < len(batch) < 12000
    assert_same_as_python_can(batch, expected[: len(batch)])
    assert ctx.problems.count >= 1
    assert any("file ends inside a container" in p.message for p in ctx.problems.shown)
    with pytest.raises(InputError, match=r"cut\.blf:offset \d+: "):
        run(blf.read, cut, strict=True, source="cut.blf")


def test_decompression_bomb_is_refused(written, monkeypatch):
    monkeypatch.setattr(blf, "MAX_CONTAINER", 50000)
    batch, ctx, _ = run(blf.read, written)
    if "w0" in written.name:  # plain containers of 128 KiB are bigger than the limit
        assert any("absurd" in p.message for p in ctx.problems.shown)
    else:
        assert any("inflates beyond" in p.message for p in ctx.problems.shown)
    assert len(batch) < 12000


def _container(payload: bytes) -> bytes:
    body = struct.pack("<H6xL4x", 2, len(payload)) + zlib.compress(payload)
    size = 16 + len(body)
    return struct.pack("<4sHHLL", b"LOBJ", 16, 1, size, 10) + body + bytes(size % 4)


def test_garbage_between_records_is_skipped_and_counted(tmp_path):
    src = tmp_path / "one.blf"
    with can.BLFWriter(str(src), compression_level=0) as w:
        for m in _messages(3):
            w.on_message_received(m)
    raw = src.read_bytes()
    header_size = struct.unpack_from("<L", raw, 4)[0]
    # one CAN_MESSAGE record, then 8 junk bytes, then the same record again
    record = raw[raw.index(b"LOBJ", header_size + 32) :][:48]
    assert struct.unpack_from("<L", record, 12)[0] == 1
    data = bytearray(raw[:header_size] + _container(record + b"JUNKJUNK" + record))
    struct.pack_into("<Q", data, 16, len(data))  # the header's file size (else: "cut short?")
    data = bytes(data)
    batch, ctx, _ = run(blf.read, data)
    # the record before the junk is not believed either: its end may be the damage
    assert len(batch) == 1 and batch.line.tolist() == [2]
    assert ctx.problems.count == 1
    assert ctx.problems.shown[0].message == (
        "damaged BLF data from byte 0 of this container's data: skipped 56 bytes to the next"
        " sound object (first: a type 1 object not followed by another)"
    )


def test_not_blf_is_a_problem():
    batch, ctx, _ = run(blf.read, b"hello world, not a BLF at all" * 10, source="x.blf")
    assert len(batch) == 0 and ctx.problems.count == 1
    assert blf.sniff(real_file("hardbyte__python-can/test_CanMessage.blf").read_bytes())
    assert not blf.sniff(b"date Sat Sep 30\nbase hex")


def test_runs_of_one_record_type_broken_by_others(tmp_path):
    """Uniform runs are read in bulk; FD and error records in between end a run."""
    rnd = random.Random(11)
    msgs = []
    for i in range(6000):
        r = rnd.random()
        kw = {"timestamp": 1700000000.0 + i * 0.001, "channel": rnd.randrange(2)}
        if r < 0.03:
            msgs.append(can.Message(is_error_frame=True, **kw))
        elif r < 0.08:
            data = bytes(rnd.randrange(256) for _ in range(rnd.choice([12, 20, 64])))
            msgs.append(can.Message(arbitration_id=0x181, is_fd=True, data=data, **kw))
        else:
            msgs.append(
                can.Message(arbitration_id=rnd.randrange(0x800), data=bytes(rnd.randrange(9)), **kw)
            )
    path = tmp_path / "mixed.blf"
    with can.BLFWriter(str(path)) as w:
        for m in msgs:
            w.on_message_received(m)
    batch, ctx, _ = run(blf.read, path, batch_size=1000)
    expected = list(can.BLFReader(str(path)))
    assert len(batch) == len(expected) == 6000
    assert_same_as_python_can(batch, expected)
    assert batch.line.tolist() == list(range(1, 6001))
    assert ctx.problems.count == 0


def test_bytes_past_the_dlc_are_dropped_in_bulk_runs(tmp_path):
    """A run of equal CAN_MESSAGE records is read through one strided view; data bytes
    stored past the DLC (and in remote frames) must still come out as nothing."""
    path = tmp_path / "dirty.blf"
    msgs = [
        can.Message(
            timestamp=1700000000.0 + i * 0.001,
            arbitration_id=0x180 + i % 5,
            data=b"\xaa" * 8,
            dlc=i % 9,
            is_remote_frame=i % 50 == 7,
            check=False,
        )
        for i in range(3000)
    ]
    with can.BLFWriter(str(path), compression_level=0) as w:
        for m in msgs:
            w.on_message_received(m)
    batch, ctx, _ = run(blf.read, path, batch_size=700)
    assert len(batch) == 3000 and ctx.problems.count == 0
    assert batch.dlc.tolist() == [i % 9 for i in range(3000)]
    for i in range(3000):
        want = (b"\0" if i % 50 == 7 else b"\xaa") * (i % 9)
        assert batch.payload(i) == want, i
    assert set(batch.channels) == {batch.channels[0]} and not batch.channel.any()


def test_empty_fd_records_at_the_end_of_a_container(tmp_path):
    """FD records whose 8-byte data slot would run past the end of the buffer."""
    path = tmp_path / "fd_empty.blf"
    msgs = [
        can.Message(timestamp=1.0 + i, arbitration_id=0x100 + i, is_fd=True, data=b"")
        for i in range(40)
    ]
    with can.BLFWriter(str(path), compression_level=0) as w:
        for m in msgs:
            w.on_message_received(m)
    batch, ctx, _ = run(blf.read, path)
    expected = list(can.BLFReader(str(path)))
    assert len(batch) == len(expected) == 40 and ctx.problems.count == 0
    assert_same_as_python_can(batch, expected)
    assert all(f & FLAG_FD for f in batch.flags) and not batch.dlc.any()


def _containers(data: bytes) -> list[int]:
    """Offsets of the LOG_CONTAINER objects of a BLF file's bytes."""
    out, pos = [], struct.unpack_from("<L", data, 4)[0]  # file header size
    while pos + 16 <= len(data):
        _, _, _, size, kind = struct.unpack_from("<4sHHLL", data, pos)
        if kind == blf.LOG_CONTAINER:
            out.append(pos)
        pos += size + size % 4
    return out


@pytest.mark.parametrize("parse_bytes", [1, 100_000])
def test_parsing_containers_together_changes_nothing(written, tmp_path, monkeypatch, parse_bytes):
    """Containers parsed one by one, a few together or all together: same rows, same problems."""
    data = bytearray(written.read_bytes())
    starts = _containers(bytes(data))
    assert len(starts) >= 4
    # a corrupt container in the middle: its records are lost, the next one starts mid-record
    mid = starts[len(starts) // 2]
    data[mid + 32 : mid + 48] = b"\xff" * 16
    bad = tmp_path / "bad.blf"
    bad.write_bytes(bytes(data))
    for path in (written, bad):
        ref, ref_ctx, ref_batches = run(blf.read, path, batch_size=4000)
        monkeypatch.setattr(blf, "PARSE_BYTES", parse_bytes)
        got, ctx, batches = run(blf.read, path, batch_size=4000)
        monkeypatch.undo()
        assert [len(b) for b in batches] == [len(b) for b in ref_batches]
        for col in ("t", "can_id", "flags", "dlc", "data", "channel", "line"):
            assert (getattr(got, col) == getattr(ref, col)).all(), col
        assert ctx.problems.shown == ref_ctx.problems.shown
        assert ctx.problems.count == ref_ctx.problems.count
    if written.name == "w6.blf":  # the zlib error, then the record it broke off
        assert [p.message.split(" (")[0] for p in ref_ctx.problems.shown] == [
            "corrupt zlib data",
            "damaged BLF data from byte 131056 of this container's data: skipped 16 bytes"
            " to the next sound object",
        ]


@pytest.mark.skipif(blf._fast_zlib is None, reason="python-isal not installed")
def test_fast_inflate_same_outcome_as_zlib(written, monkeypatch):
    """python-isal and the standard zlib give the same bytes and problems, sound or broken."""
    data = written.read_bytes()
    payloads = []
    for pos in _containers(data):
        size = struct.unpack_from("<L", data, pos + 8)[0]
        payloads.append(data[pos + 32 : pos + size])
    good = zlib.compress(b"x" * 5000)
    cases = payloads + [
        good,
        good[:-7],  # cut short: incomplete
        b"\x78\x9c" + b"\xff" * 40,  # corrupt
        b"",
        zlib.compress(bytes(300_000)),  # inflates beyond the limit below
    ]
    for payload in cases:
        fast = blf._inflate(payload, 200_000)
        monkeypatch.setattr(blf, "_fast_zlib", None)
        ref = blf._inflate(payload, 200_000)
        monkeypatch.undo()
        assert fast == ref
    if written.name == "w6.blf":  # compressed containers: all sound
        assert all(blf._inflate(p, blf.MAX_CONTAINER)[1] is None for p in payloads)


def _blf_parts(path) -> tuple[bytes, bytes]:
    """A BLF's file header and the inflated bytes of all its containers."""
    data = path.read_bytes()
    hs = struct.unpack_from("<I", data, 4)[0]
    pos, inner = hs, bytearray()
    while pos + 16 <= len(data):
        size = struct.unpack_from("<I", data, pos + 8)[0]
        method = struct.unpack_from("<H", data, pos + 16)[0]
        body = data[pos + 32 : pos + size]
        inner += zlib.decompress(body) if method == 2 else body
        pos += size + size % 4
    return data[:hs], bytes(inner)


def _plain_file(head: bytes, inner: bytes) -> bytes:
    """A BLF of one plain container holding `inner` (the file size set)."""
    size = 32 + len(inner)
    out = bytearray(head)
    out += b"LOBJ" + struct.pack("<HHLL", 16, 1, size, 10)
    out += struct.pack("<H6xL4x", 0, len(inner)) + inner + bytes(size % 4)
    struct.pack_into("<Q", out, 16, len(out))
    return bytes(out)


def _fd64(ext_off: int, stored: bytes, valid: int) -> bytes:
    """One CAN_FD_MESSAGE_64 record (object header v1) storing `stored`, claiming `valid`."""
    body = struct.pack("<BBBBIII", 1, 13, valid, 0, 0x123, 0, 0x1000)
    body = body.ljust(34, b"\0") + bytes([0, ext_off]) + bytes(4) + stored
    size = 32 + len(body)
    head = b"LOBJ" + struct.pack("<HHLL", 32, 1, size, 101) + struct.pack("<LHHQ", 2, 0, 0, 10**9)
    return head + body + bytes(-size % 4)


def test_fd64_extension_offset_beyond_the_object(tmp_path):
    """The payload ends with its object, whatever offset the record claims (once read
    beyond it, through the end of the buffer: bytes repeated from elsewhere)."""
    head, _ = _blf_parts(real_file("hardbyte__python-can/test_CanFdMessage64.blf"))
    path = tmp_path / "ext.blf"
    path.write_bytes(_plain_file(head, _fd64(250, b"\x11\x22\x33\x44", 12)))
    batch, ctx, _ = run(blf.read, path)
    assert batch.payload(0) == b"\x11\x22\x33\x44" + bytes(8)
    assert batch.data[0].tobytes() == b"\x11\x22\x33\x44" + bytes(4)
    assert ctx.problems.count == 0


def test_header_shorter_than_its_time_at_the_end_of_a_buffer(tmp_path):
    """A CAN_MESSAGE whose header size is 0 and object size 16, the last object of the
    data: it was read through the end of the buffer (an IndexError, a traceback)."""
    head, data = _blf_parts(real_file("hardbyte__python-can/test_CanMessage.blf"))
    short = b"LOBJ" + struct.pack("<HHLL", 0, 1, 16, 1)
    path = tmp_path / "short.blf"
    path.write_bytes(_plain_file(head, data + short))
    batch, ctx, _ = run(blf.read, path)
    assert len(batch) == len(
        list(can.BLFReader(str(real_file("hardbyte__python-can/test_CanMessage.blf"))))
    )
    assert [p.message for p in ctx.problems.shown] == [
        "damaged BLF data from byte 212 of this container's data: skipped 16 bytes to the next"
        " sound object (first: a type 1 object with a v1 header of 0 bytes)"
    ]


GOOD = zlib.compress(b"x" * 5000)


def _bodies(data: bytes) -> list[bytes]:
    """The compressed bodies of a BLF file's containers."""
    out = []
    for pos in _containers(data):
        size = struct.unpack_from("<L", data, pos + 8)[0]
        out.append(data[pos + 32 : pos + size])
    return out


def _inflate_cases(data: bytes) -> list[bytes]:
    """Every container body of a written file, then sound and broken zlib streams."""
    return (
        _bodies(data)
        + [
            GOOD,
            GOOD + b"trailing",  # bytes after the stream: ignored by zlib too
            GOOD[:-2],  # the checksum cut: incomplete
            b"\x78\x9c" + b"\xff" * 40,  # corrupt
            zlib.compress(bytes(150_000), 9),  # 1000:1, small enough for one call under the limit
            zlib.compress(bytes(300_000), 9),  # inflates beyond the limit
        ]
    )


@pytest.mark.skipif(blf._fast_zlib is None, reason="python-isal not installed")
def test_inflate_in_one_call_whatever_size_the_container_declares(written, monkeypatch):
    """A container is inflated in one call into the size it declares (no regrowth copies):
    a true, short, long or absurd declared size gives zlib's bytes and problems, and a
    sound container never needs the stream object."""
    data = written.read_bytes()
    payloads, good, cases = _bodies(data), GOOD, _inflate_cases(data)
    limit = 200_000
    for payload in cases:
        monkeypatch.setattr(blf, "_fast_zlib", None)
        ref = blf._inflate(payload, limit)
        monkeypatch.undo()
        true = len(ref[0])
        for size in (0, 1, true // 2, true, true + 1000, limit, limit + 1):
            assert blf._inflate(payload, limit, size) == ref, size

    def no_stream(*_a, **_k):
        raise AssertionError("a sound container went through the stream object")

    isal = blf._fast_zlib
    one_call = SimpleNamespace(
        decompress=isal.decompress, decompressobj=no_stream, error=isal.error
    )
    monkeypatch.setattr(blf, "_fast_zlib", one_call)
    assert blf._inflate(good, limit, 5000) == (b"x" * 5000, None)
    if written.name == "w6.blf":
        for p in payloads:
            assert blf._inflate(p, blf.MAX_CONTAINER, 131072)[1] is None


def _inflated_into(body: bytes, size: int) -> tuple[bytes, str | None, int]:
    """What `_Inflated.inflate` puts in its buffer for one container body, its error
    text, and the bytes the buffer held before (a tail of 5 bytes is put there first)."""
    got = blf._Inflated(None)  # type: ignore[arg-type]
    got.add(b"tail!")
    err = got.inflate(body, 16, size)
    return bytes(got.view[5 : got.fill]), err, got.pieces


@pytest.mark.skipif(blf._libdeflate is None, reason="libdeflate not on this system")
def test_libdeflate_into_the_buffer_same_outcome_as_zlib(written, monkeypatch):
    """libdeflate, inflating straight into the walk's buffer, gives the bytes and problems
    of the reference (`_inflate`, zlib) for sound and broken containers, whatever size
    they declare; a plain sound container goes through libdeflate alone."""
    good = GOOD
    cases = _inflate_cases(written.read_bytes()) + [
        good[:3],
        b"\x08\x1d" + good[2:],  # a 256-byte window (header byte not 0x78): the reference
        b"",
    ]
    for payload in cases:
        ref = blf._inflate(payload, blf.MAX_CONTAINER)
        true = len(ref[0])
        for size in (0, 1, true // 2, true, true + 1000, blf.MAX_CONTAINER + 1):
            body = bytes(16) + payload
            got = _inflated_into(body, size)
            monkeypatch.setattr(blf, "_libdeflate", None)
            assert got == _inflated_into(body, size) == (ref[0], ref[1], 2), size
            monkeypatch.undo()

    def no_fallback(*_a, **_k):
        raise AssertionError("a sound container was inflated twice")

    monkeypatch.setattr(blf, "_inflate", no_fallback)
    assert _inflated_into(bytes(16) + good, 5000) == (b"x" * 5000, None, 2)


def test_buffer_grows_and_keeps_the_tail(monkeypatch):
    """Containers larger than the buffer make it grow, keeping what it holds."""
    monkeypatch.setattr(blf, "PARSE_BYTES", 16)
    got = blf._Inflated(None)  # type: ignore[arg-type]
    big = bytes(range(256)) * 20000
    got.add(b"tail!")
    assert got.inflate(bytes(16) + zlib.compress(big), 16, len(big)) is None
    got.add(b"end")
    assert bytes(got.view[: got.fill]) == b"tail!" + big + b"end"


def test_reads_in_threads_at_once(written):
    """Each read has its own inflate state (a libdeflate decompressor is not shared):
    BLF files read in several threads at once give the rows of one read alone."""
    from concurrent.futures import ThreadPoolExecutor

    ref, _, _ = run(blf.read, written)
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda _: run(blf.read, written)[0], range(8)))
    for b in got:
        for col in ("t", "can_id", "flags", "dlc", "data", "channel", "line"):
            assert (getattr(b, col) == getattr(ref, col)).all(), col
