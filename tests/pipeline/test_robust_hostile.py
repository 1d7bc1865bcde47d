"""Hostile input, round two (issue 24): each defect the second campaign found, on a file
the test makes. Each test fails on the code before its fix."""

from __future__ import annotations

import gzip
import subprocess
import sys
import time

import pytest
from conftest import ROOT
from exported import TABLES

from cananalyze.formats.source import open_log, read_all

CANDUMP = [
    f"({1.0 + i * 0.01:.6f}) can0 {0x181 + i % 3:03X}#{i % 256:02X}11223344" for i in range(185)
]
ASC = """date Mon Jan 6 12:00:00.000 pm 2025
base hex  timestamps absolute
no internal events logged
Begin Triggerblock Mon Jan 6 12:00:00.000 pm 2025
   0.010000 1  181             Rx   d 2 01 02
   0.020000 1  182             Rx   d 2 03 04
   0.030000 1  183             Rx   d 2 05 06
End TriggerBlock
"""


def cli(*args: str, stdin=None, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        stdin=stdin,
        timeout=120,
        **kw,
    )


def _frames(path) -> list[tuple]:
    b = read_all(path)
    return [(round(float(t), 6), int(i)) for t, i in zip(b.t, b.can_id, strict=True)]


# item 10: line endings and byte-order marks
def test_cr_only_line_ends_keep_every_frame(tmp_path):
    plain, mac = tmp_path / "lf.log", tmp_path / "cr.log"
    plain.write_text("\n".join(CANDUMP) + "\n")
    mac.write_bytes(("\r".join(CANDUMP) + "\r").encode())
    assert len(_frames(mac)) == 185
    assert _frames(mac) == _frames(plain)


def test_utf8_bom_keeps_the_first_candump_frame(tmp_path):
    p = tmp_path / "bom.log"
    p.write_bytes(b"\xef\xbb\xbf" + ("\n".join(CANDUMP) + "\n").encode())
    src = open_log(p)
    got = [fb for fb in src.batches()]
    assert sum(len(fb) for fb in got) == 185
    assert src.problems.count == 0


def test_utf8_bom_keeps_the_asc_date_header(tmp_path):
    plain, bom = tmp_path / "a.asc", tmp_path / "b.asc"
    plain.write_text(ASC)
    bom.write_bytes(b"\xef\xbb\xbf" + ASC.encode())
    t = read_all(bom).t
    assert t[0] > 1.7e9  # absolute: the date header was read
    assert _frames(bom) == _frames(plain)


# item 9: the ASC sniffer was quadratic on blank lines
def test_blank_lines_sniff_in_linear_time(tmp_path):
    p = tmp_path / "blank.log.gz"
    p.write_bytes(gzip.compress(b"\n" * 65536))
    t0 = time.process_time()
    done = cli("decode", str(p))
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "not a log" in done.stderr
    assert time.process_time() - t0 < 5
    from cananalyze.formats.logs import asc, trc

    head = b"\n" * 65536
    t0 = time.process_time()
    assert not asc.sniff(head) and not trc.sniff(head)
    assert time.process_time() - t0 < 1.0  # was 16-50 s


def test_log_then_many_blank_lines(tmp_path):
    p = tmp_path / "tail.log.gz"
    p.write_bytes(gzip.compress(("\n".join(CANDUMP) + "\n").encode() + b"\n" * 2_000_000))
    t0 = time.process_time()
    assert len(read_all(p)) == 185
    assert time.process_time() - t0 < 10


# item 11: detection reads 64 KiB, not one 8 KB buffer
def test_trc_v1_whose_frames_start_past_8k(tmp_path):
    comment = "".join(f";   comment line {i:05d} of a long PEAK header block\n" for i in range(400))
    assert len(comment) > 16384
    rows = "".join(
        f"{i + 1:6d}) {1000 + i * 10:9d}  {0x181:08X}  2  {i % 256:02X} 01\n" for i in range(50)
    )
    p = tmp_path / "long.trc"
    p.write_text(comment + rows)
    got = read_all(p)
    assert len(got) == 50
    gz = tmp_path / "long.trc.gz"
    gz.write_bytes(gzip.compress(p.read_bytes()))
    assert _frames(gz) == _frames(p)


def test_stdin_sniffs_past_one_pipe_read(tmp_path):
    comment = "".join(f";   comment line {i:05d} of a long PEAK header block\n" for i in range(400))
    rows = "".join(
        f"{i + 1:6d}) {1000 + i * 10:9d}  {0x181:08X}  2  {i % 256:02X} 01\n" for i in range(50)
    )
    done = cli("decode", "--summary", "-", input=comment + rows)
    assert done.returncode == 0, done.stderr
    assert "frames: 50" in done.stdout


# item 8: closed stdin, /dev/null as the MCAP output
def test_closed_stdin_is_one_line(tmp_path):
    done = cli("decode", "-", stdin=subprocess.DEVNULL, pass_fds=())
    assert "Traceback" not in done.stderr
    closed = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", "-"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        preexec_fn=lambda: __import__("os").close(0),
    )
    assert closed.returncode == 2, closed.stderr
    assert closed.stderr.strip().splitlines() == [
        "cananalyze: error: -: standard input is closed, nothing to read"
    ]


# items 5 and 6: hostile configuration files, the one reader (network/filelines.py)
def _laughs(levels: int = 9) -> str:
    text = "a0: &a0 [x, x, x, x, x, x, x, x, x]\n"
    for i in range(1, levels + 1):
        text += f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]\n"
    return text


CONFIG_CASES = {
    "laughs.yaml": (_laughs().encode(), "expands to more than 1,000,000 values"),
    "self.yaml": (b"nodes: &a {3: *a}\n", "alias *a refers to itself"),
    "deep.yaml": (b"[" * 100_000 + b"]" * 100_000, "nests deeper than 64 levels"),
    "deepmap.yaml": (b"{a: " * 5000 + b"1" + b"}" * 5000, "nests deeper than 64 levels"),
    "deep.toml": (b"a = " + b"[" * 100_000 + b"]" * 100_000, "nests deeper than 64 levels"),
    "deeptable.toml": (b"a = " + b"{b = " * 3000 + b"1" + b"}" * 3000, "nests deeper"),
    "latin1.yaml": (b"nodes:\n  5: {name: caf\xe9}\n", ":2: network file is not UTF-8"),
    "huge.yaml": (b"# " + b"x" * (5 << 20) + b"\n", "is larger than 4 MiB"),
    "digits.yaml": (b"bitrate: " + b"9" * 100_000 + b"\n", "Exceeds the limit (4300 digits)"),
    "digits.toml": (b"bitrate = " + b"9" * 100_000 + b"\n", "Exceeds the limit (4300 digits)"),
    "vtab.yaml": (b"\x0b", "not valid YAML: unacceptable character"),  # was two lines
}


@pytest.mark.parametrize("name", sorted(CONFIG_CASES))
def test_hostile_network_file_is_one_line(tmp_path, name):
    import resource

    data, said = CONFIG_CASES[name]
    p = tmp_path / name
    p.write_bytes(data)
    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")
    limit = lambda: resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))  # noqa: E731
    for args in (["decode", "--summary", "--network", str(p)], ["check", "--rules", str(p)]):
        done = cli(*args, str(log), preexec_fn=limit)
        assert done.returncode == 2, done.stderr[-500:]
        (line,) = done.stderr.strip().splitlines()
        said_here = said.replace("network file", "rules file") if "check" in args else said
        assert said_here in line and str(p.name) in line


def test_dev_zero_as_a_configuration_file(tmp_path):
    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")
    for args in (["decode", "--network", "/dev/zero"], ["check", "--rules", "/dev/zero"]):
        done = cli(*args, str(log))
        assert done.returncode == 2
        assert done.stderr.strip().endswith(
            "/dev/zero: "
            + args[0].replace("decode", "network").replace("check", "rules")
            + " file is larger than 4 MiB"
        )


@pytest.mark.parametrize(
    "text, said",
    [
        ("assert:\n  - sdo: {max_latency_ms: 1e999}\n", ":2: max_latency_ms: inf is not a finite"),
        ("assert:\n  - heartbeat: {node: 3, period_ms: 1e999}\n", ":2: period_ms: inf is not"),
        ("assert:\n  - heartbeat: {node: 3, period_ms: soon}\n", "expected a number, got 'soon'"),
        ("assert:\n  - heartbeat: {node: 3.5, period_ms: 100}\n", "node: expected an integer"),
        ("tolerance: 1e999\n", ":1: tolerance is a fraction"),
        ("network: {nodes: [1, 2]}\n", "network.nodes: expected a table keyed by node-ID"),
    ],
)
def test_rules_file_values(tmp_path, text, said):
    p = tmp_path / "r.yaml"
    p.write_text(text)
    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")
    done = cli("check", "--rules", str(p), str(log))
    assert done.returncode == 2, done.stderr[-800:]
    (line,) = done.stderr.strip().splitlines()
    assert said in line


def test_rules_numbers_yaml_reads_as_text_still_work(tmp_path):
    """`1e2` (no dot) is text to YAML; it was taken as 100 before and still is."""
    from cananalyze.checks.rulesfile import load_rules

    p = tmp_path / "r.yaml"
    p.write_text(
        "assert:\n  - heartbeat: {node: 3, period_ms: 1e2}\n"
        "  - pdo_rate: {cob_id: '0x285', min_hz: 1, max_hz: .inf}\n"
    )
    rules, _ = load_rules(p)
    hb = [r for r in rules if r.name == "assert_heartbeat"][0]
    assert hb.period == 100.0


def _blf(path, frames: int = 200, t0: float = 1.0) -> None:
    import can

    with can.BLFWriter(str(path)) as w:
        for i in range(frames):
            w.on_message_received(
                can.Message(
                    timestamp=t0 + i * 0.01,
                    arbitration_id=0x181 + i % 3,
                    data=bytes([i % 256, 1, 2, 3]),
                    is_extended_id=False,
                )
            )


def _hidden(folder) -> list[str]:
    return sorted(p.name for p in folder.rglob(".*"))


# item 1: a log that yields no frame, exported to Parquet
def test_parquet_of_a_header_only_blf(tmp_path):
    import pyarrow.parquet as pq

    log = tmp_path / "empty.blf"
    _blf(log, 0)
    done = cli("export", str(log), "--parquet", str(tmp_path / "pq"), "--csv", str(tmp_path / "c"))
    assert done.returncode == 0, done.stderr[-800:]
    frames = pq.read_table(tmp_path / "pq" / "frames.parquet")
    assert frames.num_rows == 0 and "channel" in frames.column_names
    assert _hidden(tmp_path) == []


def test_failed_rewrite_leaves_no_rw_file(tmp_path, monkeypatch):
    from cananalyze.outputs.tables import writer
    from cananalyze.outputs.tables.stream import TableSink
    from cananalyze.pipeline import Options, build_decoder, open_source, run

    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")

    def boom(*a, **k):
        raise RuntimeError("rewrite failed")

    monkeypatch.setattr(writer, "_recode", boom)
    out = tmp_path / "pq"
    monkeypatch.setattr(  # the channel column re-coded, as when channels came out of order
        TableSink,
        "_finish_frames",
        lambda self: writer.rewrite(self.sinks["frames"], {"channel": ["zz", "can0"]}),
    )
    sink = TableSink(out, "parquet")
    opts = Options()
    with pytest.raises(RuntimeError, match="rewrite failed"):
        run(open_source(str(log), opts), build_decoder(opts), [sink], opts)
    assert _hidden(tmp_path) == [] and not list(out.glob("*"))


# item 8: MCAP offsets from a device that cannot tell(); item 16: error messages name the file
def test_mcap_to_dev_null(tmp_path):
    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")
    done = cli("decode", str(log), "--mcap", "/dev/null")
    assert done.returncode == 0, done.stderr[-800:]


def _full_disk(limit: int):
    def apply():
        import resource
        import signal

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # write() fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return apply


@pytest.mark.parametrize(
    "args",
    [
        ["export", "--parquet", "OUT"],
        ["export", "--csv", "OUT"],
        ["export", "--mcap", "OUT"],
        ["export", "--rrd", "OUT"],
        ["decode", "-o", "OUT"],
        ["decode", "--format", "jsonl", "-o", "OUT"],
    ],
)
def test_full_disk_names_the_output(tmp_path, args):
    import os

    log = tmp_path / "in" / "x.log"
    log.parent.mkdir()
    log.write_text("\n".join(CANDUMP * 20) + "\n")
    out = tmp_path / "o" / "result"
    out.parent.mkdir()
    argv = [a.replace("OUT", str(out)) for a in args]
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")  # a cut .pyc would break later runs
    done = cli(argv[0], str(log), *argv[1:], preexec_fn=_full_disk(3000), env=env)
    assert done.returncode == 2, done.stderr[-800:]
    # rerun's own logger adds its lines (coloured, no traceback); ours is the one to read
    (ours,) = [ln for ln in done.stderr.splitlines() if ln.startswith("cananalyze: error:")]
    assert ours.startswith(f"cananalyze: error: {out}: "), ours
    assert "Traceback" not in done.stderr
    assert _hidden(out.parent) == [] and not out.exists()


def test_rrd_on_dev_full(tmp_path):
    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")
    done = cli("export", str(log), "--rrd", "/dev/full")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "/dev/full: cannot write the Rerun recording" in done.stderr.strip().splitlines()[-1]


# item 14: an export is all or nothing; SIGTERM is Ctrl-C
def test_one_failing_output_commits_none(tmp_path):
    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")
    out = tmp_path / "o"
    out.mkdir()
    done = cli(
        "export", str(log), "--parquet", str(out / "pq"), "--rrd", str(out / "x.rrd"),
        "--mcap", "/dev/full",
    )  # fmt: skip
    assert done.returncode == 2, done.stderr[-500:]
    assert "/dev/full" in done.stderr
    assert sorted(p.name for p in out.rglob("*")) in ([], ["pq"])


def test_check_reports_are_committed_with_the_other_outputs(tmp_path):
    """JUnit, JSON and the HTML page appear only when every output of the run finished:
    an output failing after them leaves none of them (and no temporary file)."""
    from cananalyze.outputs.findings import FindingsSink
    from cananalyze.outputs.report.sink import ReportSink
    from cananalyze.pipeline import Options, build_checker, build_decoder, open_source, run
    from cananalyze.pipeline.sink import Sink

    class Full(Sink):
        def finish(self):
            raise OSError(28, "No space left on device", str(tmp_path / "other.out"))

    opts = Options(network=str(ROOT / "samples" / "network.toml"), checks=True)
    out = tmp_path / "o"
    out.mkdir()

    def reports():
        return [
            ReportSink(out / "r.html"),
            FindingsSink(quiet=True, junit=str(out / "j.xml"), json_file=str(out / "f.json")),
        ]

    decoder = build_decoder(opts, build_checker(opts))
    with pytest.raises(OSError):
        run(open_source(ROOT / "samples" / "faults.log", opts), decoder, [*reports(), Full()], opts)
    assert sorted(p.name for p in out.iterdir()) == []
    # and without the failing output all three are there, complete
    decoder = build_decoder(opts, build_checker(opts))
    run(open_source(ROOT / "samples" / "faults.log", opts), decoder, reports(), opts)
    import json
    import xml.etree.ElementTree as ET

    assert sorted(p.name for p in out.iterdir()) == ["f.json", "j.xml", "r.html"]
    assert (
        json.loads((out / "f.json").read_text()) and ET.parse(out / "j.xml").getroot() is not None
    )


def test_pipeline_finishes_every_sink_before_committing_any(tmp_path):
    from cananalyze.pipeline import Options, build_decoder, open_source, run
    from cananalyze.pipeline.sink import Sink

    calls = []

    class Probe(Sink):
        def __init__(self, name, fail=False):
            self.name, self.fail = name, fail

        def finish(self):
            calls.append(("finish", self.name))
            if self.fail:
                raise OSError(28, "No space left on device")

        def commit(self):
            calls.append(("commit", self.name))

        def abort(self):
            calls.append(("abort", self.name))

    log = tmp_path / "x.log"
    log.write_text("\n".join(CANDUMP) + "\n")
    opts = Options()
    sinks = [Probe("a"), Probe("b", fail=True), Probe("c")]
    sinks[1].dest = str(tmp_path / "b.out")
    with pytest.raises(OSError) as err:
        run(open_source(str(log), opts), build_decoder(opts), sinks, opts)
    assert err.value.filename == str(tmp_path / "b.out")  # item 16: named
    assert calls == [("finish", "a"), ("finish", "b"), ("abort", "a"), ("abort", "b"),
                     ("abort", "c")]  # fmt: skip


@pytest.mark.parametrize("after", [0.05, 0.6, 1.5])
@pytest.mark.slow
def test_sigterm_during_export_leaves_no_temporary_file(tmp_path, after):
    import signal

    from conftest import generated_log

    log = generated_log(tmp_path, 60000)
    out = tmp_path / "out"
    out.mkdir()
    proc = subprocess.Popen(
        [sys.executable, "-m", "cananalyze", "export", str(log), "-q",
         "--parquet", str(out / "pq"), "--csv", str(out / "csv"),
         "--mcap", str(out / "x.mcap"), "--rrd", str(out / "x.rrd")],
        cwd=ROOT, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    time.sleep(after)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert "Traceback" not in err
    assert proc.returncode in (-signal.SIGTERM, 128 + signal.SIGTERM, 0), err
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    if proc.returncode != 0 and files:
        # the kill came while the outputs were committed (or after): held back until
        # every output was in place, so all of them are there and complete
        import pyarrow.parquet as pq
        from mcap.reader import make_reader

        assert len(files) == 2 * len(TABLES) + 2, files  # the tables twice, MCAP and RRD
        for f in (out / "pq").iterdir():
            pq.read_table(f)
        with open(out / "x.mcap", "rb") as f:
            assert make_reader(f).get_summary() is not None
    assert _hidden(out) == []


def test_a_signal_while_committing_waits_until_every_output_is_in_place(tmp_path):
    """SIGTERM between two outputs' renames: both appear, then the handler runs."""
    import os
    import signal

    from cananalyze.formats.source import open_log
    from cananalyze.pipeline import Options, build_decoder, run
    from cananalyze.pipeline.sink import Sink

    class Stopped(Exception):
        pass

    def handler(signum, frame):
        raise Stopped

    calls = []

    class Recorder(Sink):
        def __init__(self, name, kill=False):
            self.name, self.kill = name, kill

        def commit(self):
            calls.append(("commit", self.name))
            if self.kill:
                os.kill(os.getpid(), signal.SIGTERM)

        def abort(self):
            calls.append(("abort", self.name))

    old = signal.signal(signal.SIGTERM, handler)
    try:
        with pytest.raises(Stopped):
            run(open_log(ROOT / "samples" / "demo.log"), build_decoder(Options()),
                [Recorder("a", kill=True), Recorder("b")])  # fmt: skip
    finally:
        signal.signal(signal.SIGTERM, old)
    assert calls[:2] == [("commit", "a"), ("commit", "b")]


# items 3 and 12: BLF lengths read from the file, and resynchronising on LOBJ
def _blf_parts(path) -> tuple[bytes, list[bytes]]:
    """A BLF's file header and its top-level objects (padding included)."""
    import struct

    data = path.read_bytes()
    hs = struct.unpack_from("<I", data, 4)[0]
    objs, pos = [], hs
    while pos + 16 <= len(data):
        size = struct.unpack_from("<I", data, pos + 8)[0]
        objs.append(data[pos : pos + size + size % 4])
        pos += size + size % 4
    return data[:hs], objs


def _blf_read(path):
    src = open_log(path)
    n = sum(len(b) for b in src.batches())
    return n, [str(p) for p in src.problems.shown]


def test_blf_header_claiming_a_huge_size(tmp_path):
    import struct

    p = tmp_path / "a.blf"
    _blf(p, 200)
    d = bytearray(p.read_bytes())
    d[4:8] = struct.pack("<I", 0x7FFFFFFF)
    p.write_bytes(bytes(d))
    n, problems = _blf_read(p)
    assert n == 200
    assert "claims 2147483647 bytes" in problems[0]


def test_blf_garbage_between_containers(tmp_path):
    a, b = tmp_path / "a.blf", tmp_path / "b.blf"
    _blf(a, 200)
    _blf(b, 200, t0=10.0)
    head, first = _blf_parts(a)
    _, second = _blf_parts(b)
    p = tmp_path / "g.blf"
    p.write_bytes(head + b"".join(first) + b"\x13\x37" * 501 + b"".join(second))
    n, problems = _blf_read(p)
    assert n == 400
    assert problems == [f"{p}:offset {len(head) + sum(map(len, first))}: no BLF object (LOBJ): "
                        "skipped 1002 bytes to the next object"]  # fmt: skip
    import can

    got = []
    with pytest.raises(can.io.blf.BLFParseError):  # python-can stops at the garbage
        got.extend(can.BLFReader(str(p)))
    assert len(got) == 200


def test_blf_inner_object_claiming_60_mib(tmp_path):
    """An object inside a container claiming 60 MiB swallowed every container after it."""
    import struct
    import zlib

    a = tmp_path / "a.blf"
    _blf(a, 200)
    head, objs = _blf_parts(a)
    inner = bytearray()
    for o in objs:
        method = struct.unpack_from("<H", o, 16)[0]
        body = o[32 : struct.unpack_from("<I", o, 8)[0]]
        inner += zlib.decompress(body) if method == 2 else body
    first = bytes(inner[:48])
    bad = first[:8] + struct.pack("<I", 60 << 20) + first[12:]
    half = len(inner) // 2

    def container(data: bytes) -> bytes:
        size = 32 + len(data)
        return (
            b"LOBJ" + struct.pack("<HHLL", 16, 1, size, 10) + struct.pack("<H6xL4x", 0, len(data))
            + data + b"\0" * (size % 4)
        )  # fmt: skip

    p = tmp_path / "inner.blf"
    rest = bytes(inner[48:half])
    p.write_bytes(head + container(bad + rest) + container(bytes(inner[half:])))
    n, problems = _blf_read(p)
    assert n == 199, problems  # only the damaged record is lost
    assert "object size of 62914560 bytes" in problems[0]


# item 4: more channel names than a uint16 index holds
@pytest.mark.parametrize("pure", ["", "1"])
def test_seventy_thousand_channel_names(tmp_path, pure):
    import os

    p = tmp_path / "chans.log"
    p.write_text("".join(f"({1.0 + i * 0.001:.6f}) c{i} 181#{i % 256:02X}\n" for i in range(70000)))
    env = dict(os.environ, CANANALYZE_PURE=pure)
    done = cli("decode", "--format", "jsonl", str(p), env=env)
    assert done.returncode == 0, done.stderr[-600:]
    import json

    rows = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(rows) == 70000
    assert [r["channel"] for r in rows[:3]] == ["c0", "c1", "c2"]
    assert rows[65534]["channel"] == "c65534"
    assert {r["channel"] for r in rows[65535:]} == {"(other channels)"}
    assert [r["data"] for r in rows] == [f"{i % 256:02x}" for i in range(70000)]


# item 13: a live MCAP recording killed with SIGKILL
KILLED_RECORDER = """
import os, signal, sys
from cananalyze.core.frames import from_rows
from cananalyze.formats.record import FrameRecorder
rec = FrameRecorder(sys.argv[1])
rec._mcap.FLUSH_SECONDS = 0.0  # a chunk per batch: as a live bus gives one per second
for k in range(0, int(sys.argv[2]), 500):
    rows = [(1.0 + (k + i) * 0.001, 0x181, bytes([i % 256]) * 8, 0, 0) for i in range(500)]
    rec.write(from_rows(rows, channels=("can0",)))
os.kill(os.getpid(), signal.SIGKILL)
"""


@pytest.mark.parametrize("frames", [3000, 20000])
def test_killed_mcap_recording_keeps_its_chunks(tmp_path, frames):
    import os
    import signal

    from mcap.reader import make_reader

    path = tmp_path / "rec.mcap"
    done = subprocess.run(
        [sys.executable, "-c", KILLED_RECORDER, str(path), str(frames)],
        cwd=ROOT, capture_output=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )  # fmt: skip
    assert done.returncode == -signal.SIGKILL
    src = open_log(path)
    assert sum(len(b) for b in src.batches()) == frames  # was 0 after 3,000 frames
    assert src.problems.count == 1  # the cut end, said once
    fixed = tmp_path / "fixed.mcap"
    out = cli("export", str(path), "--mcap", str(fixed), "--no-check", "-q")
    assert out.returncode == 0, out.stderr[-500:]
    with open(fixed, "rb") as f:  # recovered: the mcap library's standard reader opens it
        summary = make_reader(f).get_summary()
    topics = {c.id: c.topic for c in summary.channels.values()}
    counts = {topics[k]: v for k, v in summary.statistics.channel_message_counts.items()}
    assert counts["/can/frames"] == frames
