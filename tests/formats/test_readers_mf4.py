"""ASAM MDF4 (.mf4) bus logging: files written by asammdf (CANedge's layout: BusChannel
1 and 2, a group per frame kind, or a group per bus) and by python-can's MF4Writer hold
the traffic of a candump log; every frame cananalyze reads from them equals what it reads
from the candump log and what python-can's MF4Reader reads from the same file."""

from __future__ import annotations

import hashlib
import json
import os
import random
import subprocess
import sys
import time
from datetime import UTC, datetime

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import REAL, ROOT
from readers_util import assert_same_as_python_can, run

from cananalyze.core.errors import InputError
from cananalyze.core.frames import FLAG_BRS, FLAG_ERR, FLAG_ESI, FLAG_EXT, FLAG_FD, FLAG_RTR
from cananalyze.formats.logs import mf4
from cananalyze.formats.source import open_log, read_all

# python-can first: importing asammdf first imports python-can halfway through asammdf's
# own import (asammdf -> canmatrix -> can), and can.io.mf4's `import asammdf` then fails,
# leaving python-can's MF4Reader without asammdf for the whole process
can = pytest.importorskip("can")
asammdf = pytest.importorskip("asammdf")

T0 = 1767225600  # 2026-01-01T00:00:00Z
FD_SIZES = (12, 16, 20, 24, 32, 48, 64)
LEN2DLC = {n: c for c, n in enumerate([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64])}


def candump_text(n: int = 400, seed: int = 3) -> str:
    """Classic CAN (11- and 29-bit), remote requests, CAN FD up to 64 bytes with BRS and
    ESI, an error frame, on can0 and can1, at distinct microsecond times."""
    rnd = random.Random(seed)
    lines = []
    t = T0 * 1_000_000
    ids = (0x181, 0x281, 0x581, 0x601, 0x701, 0x80, 0x1A2)
    for i in range(n):
        t += rnd.randrange(50, 3000)
        bus = f"can{rnd.randrange(2)}"
        stamp = f"({t // 1_000_000}.{t % 1_000_000:06d})"
        if i == 200:
            lines.append(f"{stamp} {bus} 20000080#0000000000000000")
            continue
        ext = rnd.random() < 0.2
        ident = f"{rnd.randrange(0x20000000):08X}" if ext else f"{rnd.choice(ids):03X}"
        if i % 37 == 5:
            size = rnd.randrange(9)
            lines.append(f"{stamp} {bus} {ident}#R{size if size else ''}")
        elif i % 11 == 3:
            size = rnd.choice(FD_SIZES)
            data = bytes(rnd.randrange(256) for _ in range(size)).hex().upper()
            lines.append(f"{stamp} {bus} {ident}##{rnd.choice('0123')}{data}")
        else:
            data = bytes(rnd.randrange(256) for _ in range(rnd.randrange(9))).hex().upper()
            lines.append(f"{stamp} {bus} {ident}#{data}")
    return "\n".join(lines) + "\n"


def _dtype(kind: str, width: int) -> np.dtype:
    fields = [
        (f"{kind}.BusChannel", "u1"),
        (f"{kind}.ID", "<u4"),
        (f"{kind}.IDE", "u1"),
        (f"{kind}.DLC", "u1"),
        (f"{kind}.DataLength", "u1"),
        (f"{kind}.Dir", "u1"),
    ]
    if kind != "CAN_RemoteFrame":
        fields += [(f"{kind}.DataBytes", "u1", (width,))]
        fields += [(f"{kind}.EDL", "u1"), (f"{kind}.BRS", "u1"), (f"{kind}.ESI", "u1")]
    return np.dtype(fields)


def write_mf4(path, fb, per_bus: bool = False, compression: int = 0, width: int = 64) -> None:
    """An MF4 written by asammdf from a batch's columns, CANedge's way: BusChannel 1 for
    can0 and 2 for can1, a group per frame kind (or, per_bus, per kind and bus)."""
    mdf = asammdf.MDF(version="4.10")
    mdf.header.start_time = datetime.fromtimestamp(T0, UTC)
    src = asammdf.Source(
        name="CAN",
        path="CAN",
        comment="",
        source_type=asammdf.Source.SOURCE_BUS,
        bus_type=asammdf.Source.BUS_TYPE_CAN,
    )
    bus = np.array([int(fb.channel_name(i)[-1]) + 1 for i in range(len(fb))])
    kinds = np.where(
        fb.flags & FLAG_RTR, 1, np.where(fb.flags & FLAG_ERR, 2, 0)
    )  # data, remote, error
    for k, kind in enumerate(("CAN_DataFrame", "CAN_RemoteFrame", "CAN_ErrorFrame")):
        for b in (1, 2) if per_bus else (None,):
            rows = np.flatnonzero((kinds == k) & ((bus == b) if b else True))
            if not len(rows):
                continue
            s = np.zeros(len(rows), _dtype(kind, width))
            for j, i in enumerate(rows.tolist()):
                payload = fb.payload(i)
                fd = bool(fb.flags[i] & FLAG_FD)
                s[f"{kind}.BusChannel"][j] = bus[i]
                s[f"{kind}.ID"][j] = fb.can_id[i]
                s[f"{kind}.IDE"][j] = bool(fb.flags[i] & FLAG_EXT)
                s[f"{kind}.DLC"][j] = LEN2DLC[int(fb.dlc[i])]
                s[f"{kind}.DataLength"][j] = fb.dlc[i]
                if kind != "CAN_RemoteFrame":
                    s[f"{kind}.DataBytes"][j, : len(payload)] = np.frombuffer(payload, np.uint8)
                    s[f"{kind}.EDL"][j] = fd
                    s[f"{kind}.BRS"][j] = bool(fb.flags[i] & FLAG_BRS)
                    s[f"{kind}.ESI"][j] = bool(fb.flags[i] & FLAG_ESI)
            mdf.append(
                asammdf.Signal(samples=s, timestamps=fb.t[rows] - T0, name=kind, source=src),
                acq_name=f"CAN{b or ''}",
            )
    mdf.save(path, overwrite=True, compression=compression)
    mdf.close()


@pytest.fixture(scope="module")
def traffic(tmp_path_factory):
    """(candump path, its frames as cananalyze reads them)."""
    d = tmp_path_factory.mktemp("mf4")
    log = d / "traffic.log"
    log.write_text(candump_text())
    return log, read_all(log)


def assert_same_frames(got, want, channels: dict[str, str]) -> None:
    """Every frame: time, identifier, flags, dlc, data and bus (named per `channels`)."""
    assert len(got) == len(want) > 0
    assert np.abs(got.t - want.t).max() < 1e-6
    assert got.can_id.tolist() == want.can_id.tolist()
    assert got.flags.tolist() == want.flags.tolist()
    assert got.dlc.tolist() == want.dlc.tolist()
    assert [got.payload(i) for i in range(len(got))] == [want.payload(i) for i in range(len(want))]
    assert [got.channel_name(i) for i in range(len(got))] == [
        channels[want.channel_name(i)] for i in range(len(want))
    ]


CANEDGE_BUSES = {"can0": "1", "can1": "2"}


@pytest.mark.parametrize(
    "per_bus, compression", [(False, 0), (True, 0), (False, 2), (True, 1)], ids=str
)
def test_asammdf_written_equals_candump_and_python_can(tmp_path, traffic, per_bus, compression):
    log, want = traffic
    assert {"can0", "can1"} <= set(want.channels)
    flags = set(want.flags.tolist())
    assert FLAG_EXT in flags and FLAG_RTR in flags and FLAG_ERR in flags
    assert FLAG_FD | FLAG_BRS in flags and FLAG_FD | FLAG_BRS | FLAG_ESI in flags
    assert 64 in want.dlc.tolist()
    path = tmp_path / "x.mf4"
    write_mf4(path, want, per_bus=per_bus, compression=compression)
    assert open_log(path).fmt.name == "mf4"
    got, ctx, batches = run(mf4.read, path, batch_size=64)
    assert ctx.problems.count == 0 and ctx.format == "mf4"
    assert ctx.absolute_time and ctx.start_time == T0
    assert len(batches) > 1
    assert_same_frames(got, want, CANEDGE_BUSES)
    expected = list(can.MF4Reader(str(path)))
    assert_same_as_python_can(got, expected, time_tol=1e-6, channel_offset=0)


def test_python_can_writer_equals_candump_and_python_can(tmp_path, traffic, monkeypatch):
    """python-can's MF4Writer (one group per kind, BusChannel 0 for can0, a header in
    local time: the test runs in UTC so that python-can's reader agrees)."""
    monkeypatch.setenv("TZ", "UTC")
    time.tzset()
    try:
        log, want = traffic
        want = want.take((want.flags & FLAG_ERR) == 0)  # python-can drops their bytes
        path = tmp_path / "pc.mf4"
        writer = can.MF4Writer(str(path))
        for m in can.CanutilsLogReader(str(log)):
            if not m.is_error_frame:
                writer.on_message_received(m)
        writer.stop()
        got, ctx, _ = run(mf4.read, path, batch_size=1000)
        assert ctx.problems.count == 0
        assert_same_frames(got, want, {"can0": "0", "can1": "1"})
        expected = list(can.MF4Reader(str(path)))
        assert_same_as_python_can(got, expected, time_tol=2e-6, channel_offset=0)
    finally:
        monkeypatch.undo()
        time.tzset()


def test_chunks_and_groups_merge_in_time_order(tmp_path, traffic, monkeypatch):
    """Read 7 records of a group at a time: the same frames, in time order, as at once."""
    _, want = traffic
    path = tmp_path / "g.mf4"
    write_mf4(path, want, per_bus=True)
    monkeypatch.setattr(mf4, "CHUNK", 7)
    got, ctx, batches = run(mf4.read, path, batch_size=50)
    assert ctx.problems.count == 0 and [len(b) for b in batches[:-1]] == [50] * (len(batches) - 1)
    assert np.all(np.diff(got.t) > 0)
    assert_same_frames(got, want, CANEDGE_BUSES)


def _cli(*args: str, env=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=300,
    )


def _jsonl(path, env=None) -> list[dict]:
    out = _cli("decode", str(path), "--format", "jsonl", env=env)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    return [json.loads(line) for line in out.stdout.splitlines()]


def test_cli_decode_and_export_as_the_candump_log(tmp_path, traffic):
    log, want = traffic
    write_mf4(tmp_path / "x.mf4", want, compression=2)
    path = (tmp_path / "x.mf4").rename(tmp_path / "x.MF4")  # asammdf saves as .mf4
    a, b = _jsonl(log), _jsonl(path)
    assert len(a) == len(b) >= len(want)
    for r in a:  # the bus of a frame ("channel") and of an SDO transfer ("bus")
        for key in ("channel", "bus"):
            if r.get(key) is not None:
                r[key] = CANEDGE_BUSES[r[key]]
    assert a == b

    for src, out in ((log, tmp_path / "pa"), (path, tmp_path / "pb")):
        res = _cli("export", str(src), "--parquet", str(out), "-q")
        assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    fa = pq.read_table(tmp_path / "pa" / "frames.parquet").to_pylist()
    fb = pq.read_table(tmp_path / "pb" / "frames.parquet").to_pylist()
    assert len(fa) == len(fb) == len(want)
    for r in fa:
        r["channel"] = CANEDGE_BUSES[r["channel"]]
    assert fa == fb


def test_pure_mode_reads_the_same(tmp_path, traffic):
    """CANANALYZE_PURE=1 (no compiled helper): the same records."""
    _, want = traffic
    path = tmp_path / "x.mf4"
    write_mf4(path, want)
    env = dict(os.environ, CANANALYZE_PURE="1")
    fast = _jsonl(path, env=dict(os.environ, CANANALYZE_PURE=""))
    assert _jsonl(path, env=env) == fast and len(fast) >= len(want)


def test_truncated_file_is_one_line_exit_2(tmp_path, traffic):
    _, want = traffic
    whole = tmp_path / "x.mf4"
    write_mf4(whole, want)
    raw = whole.read_bytes()
    for cut in (20, 100, len(raw) // 2, len(raw) - 1):
        path = tmp_path / f"cut{cut}.mf4"
        path.write_bytes(raw[:cut])
        out = _cli("decode", str(path))
        assert out.returncode == 2, (cut, out.stderr)
        errors = [ln for ln in out.stderr.splitlines() if ln.startswith("cananalyze: error:")]
        assert len(errors) == 1 and "Traceback" not in out.stderr, out.stderr
        assert str(path) in errors[0] and "no frame could be read" in errors[0]
        with pytest.raises(InputError, match="no frame could be read"):
            read_all(path)


def test_channel_outside_its_record_is_a_problem_not_a_crash(tmp_path, traffic):
    """A corrupt byte offset (found by fuzzing: asammdf read past its buffers, a
    segfault at the next garbage collection): that group is skipped with a problem, the
    other groups are read."""
    _, want = traffic
    path = tmp_path / "x.mf4"
    write_mf4(path, want, per_bus=True)
    mdf = asammdf.MDF(str(path))
    group = mdf.groups[1]
    esi = next(c for c in group.channels if c.name == "CAN_DataFrame.ESI")
    at, record = esi.address + 92, int(group.channel_group.samples_byte_nr)  # cn_byte_offset
    mdf.close()
    raw = bytearray(path.read_bytes())
    assert int.from_bytes(raw[at : at + 4], "little") == esi.byte_offset
    raw[at : at + 4] = (record + 83).to_bytes(4, "little")
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(raw))
    out = _cli("decode", str(bad), "--format", "jsonl")
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    assert "CAN_DataFrame.ESI ends at byte" in out.stderr and "corrupt" in out.stderr
    got, ctx, _ = run(mf4.read, bad)
    assert ctx.problems.count == 1
    bus2 = [i for i in range(len(want)) if want.channel_name(i) == "can1"]
    data2 = [i for i in bus2 if not want.flags[i] & (FLAG_RTR | FLAG_ERR)]
    assert len(got) == len(want) - len(data2)  # group 1: the data frames of bus 2


def test_inflated_size_claim_is_bounded(tmp_path, traffic):
    """A deflate block claiming 8 GiB inflated (asammdf would allocate what it claims):
    refused with a problem, the other groups read."""
    _, want = traffic
    path = tmp_path / "x.mf4"
    write_mf4(path, want, per_bus=True, compression=1)
    raw = bytearray(path.read_bytes())
    at = raw.find(b"##DZ")
    assert at > 0
    raw[at + 32 : at + 40] = (8 << 30).to_bytes(8, "little")  # dz_org_data_length
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(raw))
    got, ctx, _ = run(mf4.read, bad)
    assert ctx.problems.count == 1
    assert "claims 8,589,934,592 bytes inflated" in ctx.problems.shown[0].message
    assert 0 < len(got) < len(want)


def test_file_bytes_unchanged(tmp_path, traffic):
    """Read as given, finalised or not: asammdf finalises an UnFinMF file by writing into
    what it reads, so that is a temporary copy, never the log."""
    _, want = traffic
    path = tmp_path / "x.mf4"
    write_mf4(path, want)
    unfin = tmp_path / "unfin.mf4"
    unfin.write_bytes(b"UnFinMF " + path.read_bytes()[8:])
    for p in (path, unfin):
        before = hashlib.sha256(p.read_bytes()).hexdigest()
        mtime = p.stat().st_mtime_ns
        got = read_all(p)
        assert_same_frames(got, want, CANEDGE_BUSES)
        assert hashlib.sha256(p.read_bytes()).hexdigest() == before
        assert p.stat().st_mtime_ns == mtime


def test_gzip_and_stdin(tmp_path, traffic):
    import gzip

    _, want = traffic
    path = tmp_path / "x.mf4"
    write_mf4(path, want)
    gz = tmp_path / "x.mf4.gz"
    gz.write_bytes(gzip.compress(path.read_bytes()))
    assert_same_frames(read_all(gz), want, CANEDGE_BUSES)
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", "-", "--format", "jsonl"],
        input=path.read_bytes(),
        capture_output=True,
        cwd=ROOT,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert [json.loads(line) for line in out.stdout.decode().splitlines()] == _jsonl(path)


def test_empty_and_no_can_groups(tmp_path):
    """Bus-logging groups with no record: 0 frames, no failure; no CAN group at all: one
    line naming what the file holds."""
    empty = tmp_path / "empty.mf4"
    writer = can.MF4Writer(str(empty))
    writer.stop()
    got, ctx, _ = run(mf4.read, empty)
    assert len(got) == 0 and ctx.problems.count == 0
    assert _cli("decode", str(empty)).returncode == 0

    other = tmp_path / "signals.mf4"
    mdf = asammdf.MDF(version="4.10")
    mdf.append(asammdf.Signal(np.arange(5.0), np.arange(5.0), name="EngineSpeed"))
    mdf.save(other, overwrite=True)
    mdf.close()
    out = _cli("decode", str(other))
    assert out.returncode == 2
    assert "without CAN bus logging" in out.stderr and "EngineSpeed" in out.stderr


def test_mdf3_is_refused_in_one_line(tmp_path):
    path = tmp_path / "old.mdf"
    mdf = asammdf.MDF(version="3.30")
    mdf.append(asammdf.Signal(np.arange(5.0), np.arange(5.0), name="x"))
    mdf.save(path, overwrite=True)
    mdf.close()
    with pytest.raises(InputError, match="MDF version 3.30"):
        read_all(path)


def test_sniff():
    assert mf4.sniff(b"MDF     4.10    amdf8.8.")
    assert mf4.sniff(b"UnFinMF 4.11    CANedge")
    assert not mf4.sniff(b"MDF is a word")
    assert not mf4.sniff(b"LOGG")


def test_real_mf4_files_if_any():
    """Any .mf4 among the real public logs reads with no problem as python-can reads it."""
    files = sorted(REAL.rglob("*.mf4")) + sorted(REAL.rglob("*.MF4")) if REAL.exists() else []
    if not files:
        pytest.skip(f"no .mf4 under {REAL}")
    for path in files:
        got, ctx, _ = run(mf4.read, path)
        assert_same_as_python_can(got, list(can.MF4Reader(str(path))), channel_offset=0)


@pytest.mark.parametrize(
    "name, per_bus",
    [
        ("00000001-63BEF5CD.MF4", {"1": 1011, "2": 3013}),
        ("00000001-60B621D9.MF4", {"1": 1403, "2": 412}),
    ],
)
def test_canedge_files_read_as_python_can_reads_them(name, per_bus):
    """CANedge's own files (tests/data/canedge, CSS Electronics' examples): the newer layout
    has BusChannel, IDE, Dir and EDL as virtual channels, a constant per group by its
    conversion; read raw they were the record's index (bus "0", "1", ... one per frame,
    every identifier extended)."""
    path = ROOT / "tests" / "data" / "canedge" / name
    got, ctx, _ = run(mf4.read, path)
    assert ctx.problems.count == 0  # its empty FD groups are nothing skipped
    assert_same_as_python_can(got, list(can.MF4Reader(str(path))), channel_offset=0)
    names = [got.channel_name(i) for i in range(len(got))]
    assert {b: names.count(b) for b in set(names)} == per_bus


def test_canedge_summary_names_both_buses_and_no_empty_bus_heading():
    """`decode --summary` of a two-bus log with no CANopen on it: the frames per channel,
    and no bus heading without timing lines under it (it printed "2:" and "1:" alone)."""
    out = _cli("decode", str(ROOT / "tests/data/canedge/00000001-63BEF5CD.MF4"), "--summary")
    lines = out.stdout.splitlines()
    at = lines.index("frames per channel:")
    assert lines[at + 1].split() == ["1", "1011"] and lines[at + 2].split() == ["2", "3013"]
    assert not [x for x in lines if x.rstrip(":").isdigit()]
    assert "skipped" not in out.stdout and out.stderr == ""


def test_a_conversion_that_fails_is_a_problem_not_a_traceback(monkeypatch):
    """A damaged conversion block (asammdf raising while it converts): the group is one
    problem naming it and its record, the other groups are read."""

    def broken(self, *args, **kwargs):
        raise ValueError("bad conversion block")

    monkeypatch.setattr(asammdf.Signal, "physical", broken)
    got, ctx, _ = run(mf4.read, ROOT / "tests" / "data" / "canedge" / "00000001-63BEF5CD.MF4")
    assert len(got) == 0 and ctx.problems.count == 3  # the 3 groups with records
    text = str(ctx.problems)
    assert "record 1" in text and "bad conversion block" in text, text
