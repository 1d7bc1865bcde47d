"""Every reader against damaged input: only InputError escapes, nothing read is lost (issue 9).

Truncation at every kind of boundary must keep every frame of the complete
lines/records before the cut; junk, bad hex, odd DLCs, wild timestamps, long
lines and wrong suffixes are problems that are counted, never tracebacks.
"""

from __future__ import annotations

import gzip
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from conftest import real_file
from hypothesis import given

from cananalyze.cli.main import main
from cananalyze.core.errors import InputError
from cananalyze.formats.source import open_log, read_all
from tests.fuzz.harness import run_log
from tests.fuzz.strategies import fuzz_settings, mutated

# one or two real logs per reader (small ones: the cut sweeps read them hundreds of times)
TEXT_LOGS = {
    "candump": "RoboTrainerAID__za_experimental/candump.log",
    "candump-l": "calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log",
    "asc": "hardbyte__python-can/logfile.asc",
    "asc-fd": "hardbyte__python-can/test_CanFdMessage64.asc",
    "trc-1.0": "hardbyte__python-can/test_CanMessage_V1_0_BUS1.trc",
    "trc-1.1": "hardbyte__python-can/test_CanMessage_V1_1.trc",
    "trc-1.3": "hardbyte__python-can/test_CanMessage_V1_3.trc",
    "trc-2.1": "hardbyte__python-can/test_CanMessage_V2_1.trc",
    "ixxat": "hilch__canopen-message-interpreter/ixxat1.trc",
    "gvret": "collin80__SavvyCAN/GVRET_Log.csv",
    "canbusanalyzer": "collin80__SavvyCAN/CarBusAnalyzer.trc",
    "sevcon": "isPointless__Sevcon/can_180209_154604.txt",
}
BLF_LOGS = [
    "hardbyte__python-can/test_CanMessage.blf",
    "hardbyte__python-can/test_CanFdMessage64.blf",
]


def _read(data: bytes, name: str, tmp_path, **kw):
    path = tmp_path / name
    path.write_bytes(data)
    src = open_log(path, **kw)
    from cananalyze.core.frames import concat

    return concat(list(src.batches())), src


def _rows(batch, upto_line=None):
    keep = np.ones(len(batch), bool) if upto_line is None else batch.line <= upto_line
    b = batch.take(keep)
    return [
        (
            float(b.t[i]),
            int(b.can_id[i]),
            int(b.flags[i]),
            b.payload(i),
            b.channel_name(i),
            int(b.line[i]),
        )
        for i in range(len(b))
    ]


def _cuts(data: bytes, limit: int = 120) -> list[int]:
    """Cut points of every kind: line ends, just after them, mid-line, mid-token, the header."""
    nl = [i for i, c in enumerate(data) if c == 10]
    points = set(range(0, min(len(data), 64)))  # inside the header / first line
    for p in nl[:: max(1, len(nl) // limit)]:
        points.update((p, p + 1, p - 1, p - 5, p - 12, p - 20))
    return sorted(p for p in points if 0 <= p < len(data))


@pytest.mark.parametrize("key", sorted(TEXT_LOGS))
@pytest.mark.slow
def test_text_log_cut_anywhere_keeps_complete_lines(key, tmp_path):
    path = real_file(TEXT_LOGS[key])
    data = path.read_bytes()[:60000]
    suffix = path.suffix
    full, _ = _read(data, "full" + suffix, tmp_path)
    assert len(full) > 0
    for cut in _cuts(data):
        prefix = data[:cut]
        complete = prefix.count(b"\n") + prefix.count(b"\r") * (key == "canbusanalyzer")
        try:
            got, src = _read(prefix, "cut" + suffix, tmp_path)
        except InputError as exc:  # too little left to recognise: a one-line refusal
            assert "\n" not in str(exc)
            assert (full.line <= complete).sum() < 3, f"{key} cut at {cut}: {exc}"
            continue
        assert _rows(got, complete) == _rows(full, complete), f"{key} cut at {cut}"
        assert len(got) <= len(full) + 1


@pytest.mark.parametrize("name", BLF_LOGS)
def test_blf_cut_at_every_offset_keeps_a_prefix(name, tmp_path):
    data = real_file(name).read_bytes()
    full, _ = _read(data, "full.blf", tmp_path)
    want = _rows(full)
    some = False  # a cut has given frames: every longer one gives them too
    for cut in range(len(data)):
        try:
            got, src = _read(data[:cut], "cut.blf", tmp_path)
        except InputError as exc:
            # not even the LOGG signature left, or cut before the first frame: nothing
            # readable is a failure (issue 38), in one line
            assert "\n" not in str(exc) and not some, f"cut at {cut}: {exc}"
            assert cut < 4 or "no frame could be read" in str(exc)
            continue
        some = some or len(got) > 0
        rows = _rows(got)
        assert rows == want[: len(rows)], f"cut at {cut}"
        if cut < len(data) and len(rows) < len(want):
            assert src.problems.count >= 1, f"cut at {cut} lost frames silently"


def _blf_with(container_payload: bytes, tmp_path, method: int = 2, usize: int = 0) -> bytes:
    raw = real_file("hardbyte__python-can/test_CanMessage.blf").read_bytes()
    header_size = struct.unpack_from("<L", raw, 4)[0]
    body = struct.pack("<H6xL4x", method, usize) + container_payload
    size = 16 + len(body)
    return (
        raw[:header_size]
        + struct.pack("<4sHHLL", b"LOBJ", 16, 1, size, 10)
        + body
        + bytes(size % 4)
    )


@pytest.mark.slow
def test_blf_decompression_bomb_memory_bounded(tmp_path):
    """A container inflating to 1 GiB of zeros is refused after 64 MiB; memory stays bounded."""
    import tracemalloc

    z = zlib.compressobj(9)
    block = bytes(1 << 20)
    bomb = b"".join(z.compress(block) for _ in range(1024)) + z.flush()
    assert len(bomb) < 2 << 20
    data = _blf_with(bomb, tmp_path, usize=1 << 30)
    tracemalloc.start()
    try:
        # nothing else in the file: nothing readable, a failure naming the refusal
        with pytest.raises(InputError, match="inflates beyond .*no frame could be read"):
            _read(data, "bomb.blf", tmp_path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 300 << 20, f"peak {peak >> 20} MiB"


def test_blf_corrupt_zlib_and_unknown_compression(tmp_path):
    good = zlib.compress(b"LOBJ" + bytes(60))
    corrupt = good[:10] + bytes(b ^ 0x5A for b in good[10:])
    # nothing readable: a failure naming the first problem (issue 38), not "0 frames"
    with pytest.raises(InputError, match=r"z\.blf:offset 144: corrupt zlib.*no frame could be"):
        _read(_blf_with(corrupt, tmp_path), "z.blf", tmp_path)
    with pytest.raises(InputError, match="unknown container compression 7"):
        _read(_blf_with(good, tmp_path, method=7), "m.blf", tmp_path)


def test_gzip_ending_early_keeps_frames_before_the_cut(tmp_path):
    path = real_file("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log")
    full = read_all(path)
    packed = gzip.compress(path.read_bytes())
    for frac in (0.3, 0.6, 0.95):
        got, src = _read(packed[: int(len(packed) * frac)], "cut.log.gz", tmp_path)
        assert 0 < len(got) < len(full)
        # the line the cut broke is left out, not read as a frame of fewer bytes
        assert _rows(got) == _rows(full)[: len(got)]
        assert any("corrupt gzip at or before" in p.message for p in src.problems.shown)


def test_gzip_ending_early_strict_exits_2_after_frames(tmp_path, capsys):
    path = real_file("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log")
    packed = gzip.compress(path.read_bytes())
    cut = tmp_path / "cut.log.gz"
    cut.write_bytes(packed[: len(packed) // 2])
    rc = main(["decode", "--strict", "--format", "jsonl", str(cut)])
    out, err = capsys.readouterr()
    assert rc == 2
    assert out.count('"kind":"frame"') > 1000
    # the first problem is the gzip's end (the line it broke is left out, not misread)
    assert err.count("\n") == 1 and err.startswith("cananalyze: error:") and "cut.log.gz:" in err
    assert "corrupt gzip at or before compressed byte" in err


def test_strict_stops_at_the_bad_line_after_yielding_the_ones_before(tmp_path, capsys):
    log = tmp_path / "bad.log"
    lines = [f"({i}.000000) can0 181#{i:02X}" for i in range(1, 6)]
    lines.insert(3, "(4.500000) can0 181#0G")
    log.write_text("\n".join(lines) + "\n")
    rc = main(["decode", "--strict", "--format", "jsonl", str(log)])
    out, err = capsys.readouterr()
    assert rc == 2
    assert out.count('"kind":"frame"') == 3
    assert "bad.log:line 4:" in err and "invalid hex" in err and err.count("\n") == 1
    rc = main(["decode", "--format", "jsonl", str(log)])
    out, err = capsys.readouterr()
    assert rc == 0 and out.count('"kind":"frame"') == 5 and "1 unreadable" in err


@pytest.mark.parametrize(
    "name, body",
    [
        ("empty.log", b""),
        ("blank.asc", b"\n\n\r\n"),
        ("zeros.trc", bytes(5000)),
        ("random.blf", bytes(range(256)) * 20),
        ("binary.log", bytes((i * 7919) % 256 for i in range(20000))),
        ("eds.log", b"[FileInfo]\nFileName=x.eds\n[DeviceInfo]\nVendorName=X\n"),
        ("utf16.asc", "date Mon Jan 1\nbase hex\n".encode("utf-16")),
        ("dir.gz", b"\x1f\x8b\x08\x00garbage-after-gzip-magic"),
    ],
)
def test_unreadable_files_are_one_line_input_errors(name, body, tmp_path, capsys):
    path = tmp_path / name
    path.write_bytes(body)
    rc = main(["decode", str(path)])
    out, err = capsys.readouterr()
    assert rc == 2, err
    assert err.count("\n") == 1 and name in err and "Traceback" not in err


def test_format_follows_content_not_suffix(tmp_path):
    """A candump log named .asc, a BLF named .log, an ASC named .trc: read by content."""
    pairs = [
        ("RoboTrainerAID__za_experimental/candump.log", "x.asc"),
        ("hardbyte__python-can/test_CanMessage.blf", "x.log"),
        ("hardbyte__python-can/logfile.asc", "x.trc"),
        ("hardbyte__python-can/test_CanMessage_V2_1.trc", "x.csv"),
        ("collin80__SavvyCAN/GVRET_Log.csv", "x.blf"),
    ]
    for rel, name in pairs:
        src = real_file(rel)
        got, _ = _read(src.read_bytes(), name, tmp_path)
        assert _rows(got) == _rows(read_all(src)), name


def test_junk_lines_inside_text_logs_are_counted_not_fatal(tmp_path):
    path = real_file("calumroy__CANopen_socketCAN_Test/can_log_070825_brake_sensor_test2.log")
    lines = path.read_bytes().split(b"\n")[:400]
    junk = [
        b"\x00\x01\x02\xff\xfe binary",
        b"(12.5) can0 18G#00",
        b"(1.0) can0 181#0",
        b"(1.0) can0 181#" + b"00" * 9,
        b"(nan) can0 181#00",
        b"(1.0) can0 1234#00",
        b"(-inf) can0 181#00",
        b"\xb3\xb2\xb9",
    ]
    mixed = []
    for i, ln in enumerate(lines):
        mixed.append(ln)
        if i % 50 == 10:
            mixed.append(junk[(i // 50) % len(junk)])
    got, src = _read(b"\n".join(mixed), "mixed.log", tmp_path)
    assert len(got) == len([ln for ln in lines if ln.strip()])
    assert src.problems.count == 8
    assert np.isfinite(got.t).all()


@pytest.mark.parametrize(
    "suffix, text",
    [
        (
            ".asc",
            "date Mon Jan 1 10:00:00.000 am 2024\nbase hex  timestamps absolute\n"
            "0.1 1 181 Rx d 8 01 02\n0.2 1 181 Rx d 2 01 02 03 04\n0.3 1 -5 Rx d 1 01\n"
            "1e400 1 181 Rx d 1 01\n0.4 1 181 Rx d 1 ZZ\n0.5 1 181 Rx d 1 01\n",
        ),
        (
            ".trc",
            ";$FILEVERSION=1.1\n;$STARTTIME=1e300\n;\n   1)  1.0  Rx  0181  8  01 02\n"
            "   2)  2.0  Rx  0181  \xb3  01\n   3)  nan  Rx  0181  1  01\n   4)  3.0  Rx  0181  1  01\n",
        ),
        (
            ".trc",
            ";$FILEVERSION=1.3\n;$STARTTIME=45000.5\n;\n   1)  1.0 1\n   2)  2.0 1 Rx\n"
            "   3)  3.0 1 Rx 0181 - 1 01\n",
        ),
        (
            ".trc",
            ";$FILEVERSION=2.1\n;$STARTTIME=45000.5\n;$COLUMNS=N,O,T,B,I,d,R,L,D\n;\n"
            "      1       1.0 DT 9 0181 Rx - 8 01\n      2       2.0 DT 1 -181 Rx - 1 01\n"
            "      3       3.0 DT 1 0181 Rx - 1 01\n",
        ),
    ],
)
def test_dlc_disagreeing_with_data_and_wild_values(suffix, text, tmp_path):
    got, src = _read(text.encode("latin-1"), "w" + suffix, tmp_path)
    assert len(got) >= 1 and src.problems.count >= 1
    assert np.isfinite(got.t).all() and (got.dlc <= 64).all()
    assert all(len(got.payload(i)) == got.dlc[i] for i in range(len(got)))


def test_timestamps_backwards_and_jumps_are_kept_as_logged(tmp_path):
    times = [5.0, 4.0, 4.0, 1e9, 0.5, 1.7e9, 1.7e9 - 3600]
    log = tmp_path / "t.log"
    log.write_text("".join(f"({t:.6f}) can0 70{i % 3 + 1}#05\n" for i, t in enumerate(times)))
    got = read_all(log)
    assert got.t.tolist() == times
    rc = main(["decode", "--summary", str(log)])
    assert rc == 0


@pytest.mark.parametrize("name", ["long.asc", "long.trc", "long.log", "long.csv"])
def test_absurdly_long_line_memory_bounded(name, tmp_path):
    """A 128 MiB line with no newline is skipped with one problem, without holding it whole."""
    import tracemalloc

    heads = {
        "long.asc": b"date Mon Jan 1 10:00:00.000 am 2024\nbase hex  timestamps absolute\n0.1 1 181 Rx d 1 01\n",
        "long.trc": b";$FILEVERSION=1.1\n;\n   1)  1.0  Rx  0181  1  01\n",
        "long.log": b"(1.0) can0 181#01\n" * 3,
        "long.csv": b"Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\n1000,00000181,false,0,1,01\n",
    }
    path = tmp_path / name
    with open(path, "wb") as f:
        f.write(heads[name])
        chunk = b"A" * (1 << 20)
        for _ in range(128):
            f.write(chunk)
        f.write(b"\n" + heads[name].splitlines()[-1] + b"\n")
    tracemalloc.start()
    try:
        src = open_log(path)
        n = sum(len(b) for b in src.batches())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert n >= 2
    assert src.problems.count == 1
    assert peak < 48 << 20, f"peak {peak >> 20} MiB"  # the line is 128 MiB


@pytest.mark.parametrize("key", sorted(TEXT_LOGS))
def test_blank_lines_change_nothing_read(key, tmp_path):
    """Issue 38 item 5: blank lines (empty, CR only, spaces and tabs, runs of hundreds)
    after every line but the first of a real log of each text format, in its own line
    ends: the same frames and problems, each frame at its line in the new file."""
    data = real_file(TEXT_LOGS[key]).read_bytes()[:200_000]
    data = data[: data.rfind(b"\r" if key == "canbusanalyzer" else b"\n") + 1]
    end = b"\r" if key == "canbusanalyzer" else b"\n"
    blanks = [end, end * 300, b"\r\n" if end == b"\n" else end]
    if not key.startswith("candump"):  # (to candump, a line of spaces is a bad line)
        blanks += [b" \t " + end, b"\x0b\x0c" + end]
    out, where, line = [], [], 0
    for i, row in enumerate(data.split(end)[:-1]):
        line += 1
        where.append(line)
        out.append(row + end)
        if i:
            out.append(blanks[i % len(blanks)])
            line += blanks[i % len(blanks)].count(end)
    suffix = Path(TEXT_LOGS[key]).suffix
    plain, src0 = _read(data, "plain" + suffix, tmp_path)
    blank, src = _read(b"".join(out), "blank" + suffix, tmp_path)
    assert src.ctx.format == src0.ctx.format and len(plain) > 0
    assert [r[:-1] for r in _rows(blank)] == [r[:-1] for r in _rows(plain)]
    assert blank.line.tolist() == [where[k - 1] for k in plain.line.tolist()]
    said = lambda s: [(p.location, p.message) for p in s.ctx.problems.shown]  # noqa: E731
    assert [m for _, m in said(src)] == [m for _, m in said(src0)]


@pytest.mark.parametrize("pure", [False, True], ids=["compiled", "pure"])
def test_blank_lines_before_the_first_frame(pure, tmp_path, monkeypatch):
    """Blank lines that open a candump log (a chunk of nothing but blank lines) read the
    frames after them, on both paths; the pure path raised IndexError (CI, 2026-12-05)."""
    from cananalyze.runtime import speedups

    if pure:
        monkeypatch.setattr(speedups, "C", None)
    path = tmp_path / "lead.log"
    path.write_bytes(
        b"\n\n(1.000000) can0 601#4000100000000000\n(1.001000) can0 581#4300100092010200\n"
    )
    got = read_all(path, fmt="candump")
    assert got.line.tolist() == [3, 4]
    assert got.can_id.tolist() == [0x601, 0x581]


# ---- property tests: mutations of the real logs -------------------------------------------------

MUTATION_LOGS = [
    "RoboTrainerAID__za_experimental/candump.log",
    "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
    "hardbyte__python-can/logfile.asc",
    "hardbyte__python-can/test_CanFdMessage64.asc",
    "hardbyte__python-can/test_CanMessage.blf",
    "hardbyte__python-can/test_CanFdMessage64.blf",
    "hardbyte__python-can/test_CanMessage.asc.gz",
    "hardbyte__python-can/test_CanMessage_V1_1.trc",
    "hardbyte__python-can/test_CanMessage_V1_3.trc",
    "hardbyte__python-can/test_CanMessage_V2_1.trc",
    "isPointless__Sevcon/can_180209_154604.txt",
    "collin80__SavvyCAN/GVRET_Log.csv",
    "collin80__SavvyCAN/CarBusAnalyzer.trc",
    "hilch__canopen-message-interpreter/ixxat1.trc",
]


@pytest.mark.parametrize("rel", MUTATION_LOGS)
def test_mutated_real_logs_never_crash(rel):
    path = real_file(rel)
    data = path.read_bytes()[:6000] if not rel.endswith((".blf", ".gz")) else path.read_bytes()
    suffix = "".join(path.suffixes[-2:]) if rel.endswith(".gz") else path.suffix

    @fuzz_settings(40)
    @given(mutated(data))
    def check(blob):
        run_log(blob, suffix)
        run_log(blob, suffix, strict=True)

    check()


@pytest.fixture(scope="module")
def binary_seeds(tmp_path_factory) -> dict:
    from tests.fuzz.seeds import write_seeds

    return {p.name: p for p in write_seeds(tmp_path_factory.mktemp("seeds"))}


@pytest.mark.parametrize(
    "name",
    [
        "seed.pcap",
        "seed.pcapng",
        "sll2.pcapng",
        "seed.blf",
        # asammdf parses each mutated file for about 0.25 s: 80 of them go to the slow run
        pytest.param("seed.mf4", marks=pytest.mark.slow),
        "seed.mcap",
        "seed.log.gz",
    ],
)
def test_mutated_binary_captures_never_crash(binary_seeds, name):
    """The formats the real logs lack (pcap, pcapng, a cooked capture, MF4, MCAP, gzip), each
    from its own writer, mutated: a reader answers with frames or one InputError."""
    if name not in binary_seeds:
        pytest.skip(f"{name}: its writer is not installed")
    path = binary_seeds[name]
    data = path.read_bytes()
    suffix = ".log.gz" if name.endswith(".gz") else path.suffix
    run_log(data, suffix)  # the seed itself reads

    @fuzz_settings(40)
    @given(mutated(data))
    def check(blob):
        run_log(blob, suffix)
        run_log(blob, suffix, strict=True)

    check()


# ---- regressions: each input crashed a reader (found by the fuzzers) ---------------------------

_ASC_HEAD = "date Mon Jan 1 10:00:00.000 am 2024\nbase hex  timestamps absolute\n"
_TRC11 = ";$FILEVERSION=1.1\n;$STARTTIME=45000.5\n;\n"
_CBA_HEAD = "@ TEXT @ 2 @ 64 @ 0 @ 55 @ 10078 @ 00:00:10.078 @\r"
_GVRET_HEAD = "Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\n"


@pytest.mark.parametrize(
    "name, text, problem",
    [
        # str.isdigit() accepts superscript digits (Latin-1 0xB2/0xB3/0xB9), int() does not: ValueError
        (
            "sup.trc",
            _TRC11 + "   1)  1.0  Rx  0181  \xb3  01\n   2)  2.0  Rx  0181  1  01\n",
            "invalid DLC",
        ),
        (
            "sup.asc",
            _ASC_HEAD + "0.1 \xb3 181 Rx d 1 01\n0.2 1 181 Rx d 1 01\n",
            None,
        ),  # skipped as an event
        (
            "supfd.asc",
            _ASC_HEAD + "0.1 CANFD \xb2\xb9 Rx 181 1 0 1 1 01\n0.2 1 181 Rx d 1 01\n",
            "CANFD",
        ),
        (
            "sup.trc",
            _CBA_HEAD + "46,016\t1\t0004\t45A\t\xb3\t5A\r46,017\t1\t0004\t45A\t1\t5A\r",
            "invalid DLC",
        ),
        (
            "sup.csv",
            _GVRET_HEAD + "1000,00000181,false,0,\xb2\xb9,01\n2000,00000181,false,0,1,01\n",
            "invalid LEN",
        ),
        # int * 1e-4 on a 400-digit tick count: OverflowError
        (
            "ticks.txt",
            "0x0181   "
            + "9" * 400
            + " - d 0.2 0 PDO { 0x01 }\n"
            + "0x0181   306585 - d 0.2 0 PDO { 0x01 }\n" * 3,
            "out of range",
        ),
        # timedelta(days=1e300): OverflowError
        (
            "start.trc",
            ";$FILEVERSION=1.1\n;$STARTTIME=1e300\n;\n   1)  1.0  Rx  0181  1  01\n",
            "STARTTIME",
        ),
        # TRC 1.3 line with fewer columns than its layout: IndexError
        (
            "short.trc",
            ";$FILEVERSION=1.3\n;$STARTTIME=45000.5\n;\n   1)  1.0 1 Rx\n   2)  2.0 1 Rx 0181 - 1 01\n",
            "not a TRC 1.3",
        ),
        # int('-181', 16) is negative: OverflowError in the uint32 column
        (
            "neg.trc",
            ";$FILEVERSION=2.1\n;$STARTTIME=45000.5\n;$COLUMNS=N,O,T,B,I,d,R,L,D\n;\n"
            "      1       1.0 DT 1 -181 Rx - 1 01\n      2       2.0 DT 1 0181 Rx - 1 01\n",
            "out of range",
        ),
        # a long interface name on the first line made the bulk candump path index past its padding
        (
            "iface.log",
            "(1.0) " + "x" * 300 + " 181#01\n(2.0) can0 181#02\n(3.0) can0 18",
            "not a candump line",
        ),
    ],
)
def test_fuzzer_crash_regressions(name, text, problem, tmp_path):
    got, src = _read(text.encode("latin-1"), name, tmp_path)
    assert len(got) >= 1
    if problem is None:
        return
    assert src.problems.count >= 1 and any(problem in p.message for p in src.problems.shown), (
        src.problems.shown
    )
    with pytest.raises(InputError):
        _read(text.encode("latin-1"), name, tmp_path, strict=True)


def test_blf_cut_inside_file_header_is_reported(tmp_path):
    data = real_file("hardbyte__python-can/test_CanMessage.blf").read_bytes()
    with pytest.raises(InputError, match=r"h\.blf:offset 72: file ends inside the BLF file header"):
        _read(data[:100], "h.blf", tmp_path)
