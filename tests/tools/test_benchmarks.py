"""Every script in benchmarks/ runs on a tiny generated log, exits 0 and prints its figures,
so none of them rots while the code it measures changes. The numbers are not judged here
(a few thousand frames measure start-up); their shape is."""

from __future__ import annotations

import ctypes
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from conftest import ROOT, SAMPLES

BENCH = ROOT / "benchmarks"
sys.path.insert(0, str(BENCH))
from generate import log_stem  # noqa: E402  (the name the scripts give their logs)

SMOKED = {
    "generate.py",
    "bench_check.py",
    "bench_bounded.py",
    "bench_dbc.py",
    "bench_decode.py",
    "bench_fleet.py",
    "bench_rerun_s3.py",
    "bench_floor.py",
    "bench_live.py",
    "bench_report.py",
    "bench_pcap.py",
    "bench_mf4.py",
    "bench_tables.py",
    "bench_precision.py",
    "mem_profile.py",
    "thread_cpu.py",
    "fuzz_campaign.py",
}
NUMBER = r"\d+(\.\d+)?"


def _run(script: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    done = subprocess.run(
        [sys.executable, str(BENCH / script), *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=timeout,
    )
    assert done.returncode == 0, f"{script} exited {done.returncode}:\n{done.stderr[-2000:]}"
    return done


def test_every_benchmark_script_has_a_smoke_test():
    assert {p.name for p in BENCH.glob("*.py")} == SMOKED


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> Path:
    """3000 generated frames as candump, ASC and BLF, named as the scripts name them."""
    out = tmp_path_factory.mktemp("bench")
    stem = log_stem(out, 3000)
    done = _run("generate.py", "3000", str(stem))
    assert done.stdout.split() == [
        "wrote",
        str(stem.with_suffix(".log")),
        "wrote",
        str(stem.with_suffix(".asc")),
        "wrote",
        str(stem.with_suffix(".blf")),
    ]
    import can

    for suffix in (".log", ".asc", ".blf"):
        assert sum(1 for _ in can.LogReader(str(stem.with_suffix(suffix)))) == 3000, suffix
    return out


DEVICES = [a for k in range(1, 17) for a in ("--device", f"{k}=dat7014")]


def _check(log: Path, json_out: Path) -> tuple[int, list]:
    """`check` as bench_decode runs it (16 devices): its exit code and its findings, read
    back from --json with the json module."""
    import json

    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", "check", str(log), *DEVICES, "--json", str(json_out)],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stderr
    return done.returncode, json.loads(json_out.read_text())


def test_generated_healthy_bus_passes_check_and_faulty_bus_does_not(tmp_path):
    """The benchmarks' bus is a bus users have: `check` exits 0 with no finding on it,
    though it carries EMCYs (each saying "no error", read back by python-can); the
    --faults bus, for the checks' cost, gives findings of several rules."""
    import can

    healthy, faulty = tmp_path / "healthy", tmp_path / "faulty"
    _run("generate.py", "10000", str(healthy), ".log")
    _run("generate.py", "10000", str(faulty), ".log", "--faults")
    emcy = [
        m
        for m in can.LogReader(str(healthy.with_suffix(".log")))
        if 0x81 <= m.arbitration_id <= 0x90
    ]
    assert len(emcy) > 20 and all(bytes(m.data[:3]) == bytes(3) for m in emcy)
    code, found = _check(healthy.with_suffix(".log"), tmp_path / "h.json")
    assert code == 0 and found == []
    code, found = _check(faulty.with_suffix(".log"), tmp_path / "f.json")
    assert code == 1 and len({f["rule"] for f in found}) >= 3, found[:3]


def test_bench_check(logs):
    lines = _run("bench_check.py", "3000", "1", "--out", str(logs)).stdout.splitlines()
    assert re.fullmatch(rf"decode --summary +best CPU +{NUMBER} s +best wall +{NUMBER} s", lines[0])
    assert re.fullmatch(rf"check +best CPU +{NUMBER} s +best wall +{NUMBER} s", lines[1])
    assert re.fullmatch(rf"check overhead: [+-]{NUMBER} % CPU \(3000 frames, best of 1\)", lines[2])


@pytest.mark.slow  # a benchmark run end to end
def test_bench_bounded_rules_and_blank_lines(tmp_path):
    """A small rules file and every text format with and without blank lines: CPU and
    peak RSS printed, the same frames read both ways."""
    out = _run(
        "bench_bounded.py",
        *("--assertions", "300", "--frames", "300", "--blank", "0.2", "--repeat", "1"),
        *("--out", str(tmp_path)),
    ).stdout.splitlines()
    assert out[0] == "CPU seconds (user+system), best of 1; peak RSS, largest"
    assert re.fullmatch(
        rf"rules: check samples/demo.log --rules FILE \(300 assertions, {NUMBER} MB\)", out[1]
    )
    for line, what in zip(out[2:4], ("no rules", "rules"), strict=True):
        assert re.fullmatch(rf"  this  {what} +CPU +{NUMBER} s  peak RSS +{NUMBER} MB", line)
    assert out[4].startswith("blank lines: 300 frames, with and without 0.2 MiB")
    rows = out[5:]
    assert [r.split()[1] for r in rows] == [
        "candump", "asc", "trc", "pycan_csv", "gvret", "ixxat", "canbusanalyzer", "sevcon",
    ]  # fmt: skip
    for r in rows:
        fmt = r.split()[1]
        assert re.search(rf" 300 frames  CPU +{NUMBER} s, with blank lines +{NUMBER} s: ", r)
        assert r.endswith(f"s/MiB  (same frames, {fmt}, 0 problems)"), r
    assert not list(tmp_path.iterdir())  # the inputs are gone


def test_bench_tables_compares_each_layout(logs, tmp_path):
    """Every layout variant gets CPU, wall, size and a query figure; the chosen layout is
    smaller than the payload as hex and than signals one row per value."""
    devices = [a for k in range(1, 17) for a in ("--device", f"{k}=dat7014")]
    out = tmp_path / "pq"
    cmd = [
        sys.executable,
        "-m",
        "cananalyze",
        "export",
        str(log_stem(logs, 3000).with_suffix(".log")),
    ]
    subprocess.run([*cmd, "--parquet", str(out), *devices, "-q"], check=True, cwd=ROOT)
    done = _run("bench_tables.py", str(out), "--repeat", "1")
    rows = {}
    for line in done.stdout.splitlines()[1:-1]:
        label, figures = line[:34].strip(), line[34:].split()
        assert len(figures) == 4 and all(re.fullmatch(NUMBER, f) for f in figures), line
        rows[label] = [float(f) for f in figures]
    assert len(rows) == 14
    assert rows["frames: as written"][2] < rows["frames: data as hex text"][2]
    assert rows["signals: as written"][2] < rows["signals: one row per value"][2]
    assert done.stdout.splitlines()[-1].startswith("load average")


@pytest.mark.slow
def test_bench_fleet(tmp_path):
    """Five logs of two sizes on one real local worker, into a folder and into moto's S3 on
    127.0.0.1, each run followed by a rerun: every run complete, every figure printed."""
    pytest.importorskip("moto.server")
    pytest.importorskip("s3fs")
    out = _run(
        "bench_fleet.py",
        *("5", "500,1500", "--workers", "1", "--repeats", "1", "--out", str(tmp_path)),
        timeout=420,
    )
    lines = out.stdout.splitlines()
    assert lines[0].startswith(
        "fleet: 5 logs of 500/1,500 frames = 4,500 frames (3 candump, 1 ASC, 1 BLF)"
    )
    for storage in ("local", "s3"):
        run = next(line for line in lines if line.startswith(f"run 1 {storage} workers=1:"))
        assert re.search(rf"wall {NUMBER} s, CPU {NUMBER} s \(user\+sys", run), run
        assert re.search(rf"a task -?{NUMBER} ms \+ -?{NUMBER} us a frame", run), run
        assert re.search(rf"dataset {NUMBER} MB in 5 date partitions; rerun wall {NUMBER} s", run)
        median = next(line for line in lines if line.startswith(f"median {storage} workers=1"))
        assert re.search(rf"dataset {NUMBER} bytes a frame", median), median
    s3 = lines[-1]
    assert s3.startswith("median s3 workers=1 (1 runs)"), s3
    # every log is read (one GET each at least) and its seven parts put
    assert re.search(r"requests a log [\d.]+ \(.*GET [1-9][\d.]*.*PUT [1-9]", s3), s3


@pytest.mark.slow
def test_bench_rerun_s3(tmp_path):
    """Twenty logs already in a bucket dataset of moto's S3 on 127.0.0.1 and in a local
    one: without the dataset's `logs` index the rerun reads one GET a loose `logs` part
    (and writes the index: one PUT), with it one GET in all, loose or after `fleet
    compact`; no cluster either way."""
    pytest.importorskip("moto.server")
    pytest.importorskip("s3fs")
    out = _run(
        "bench_rerun_s3.py", "20", "--storage", "s3,local", "--out", str(tmp_path), timeout=300
    )
    lines = out.stdout.splitlines()
    assert lines[0].startswith("s3: 20 logs of "), lines
    s3 = {k: next(x for x in lines if x.startswith(f"rerun s3 {k} 1:")) for k in STATES}
    assert re.search(rf"wall {NUMBER} s, CPU {NUMBER} s, .*requests GET 2[01] ", s3["no-index"])
    assert "PUT 1" in s3["no-index"], s3
    for state in ("loose", "compacted"):
        assert re.search(r"requests GET 1 ", s3[state]) and "PUT" not in s3[state], s3
    assert all("no cluster" in x for x in s3.values()), s3
    assert any(x.startswith("compact s3: ") and "1 written" in x for x in lines), lines
    assert any(x.startswith("s3 listing: 20 keys in 1 LIST pages") for x in lines), lines
    for k in STATES:
        line = next(x for x in lines if x.startswith(f"median rerun local {k} (1 runs):"))
        assert re.search(rf"wall {NUMBER} s, CPU {NUMBER} s, peak RSS {NUMBER} MB", line), line


STATES = ("no-index", "loose", "compacted")


@pytest.mark.slow
def test_bench_decode_prints_every_figure(logs):
    out = _run(
        "bench_decode.py",
        *("--size", "3000", "--formats", ".log", "--repeat", "1", "--pycan-prefix", "0"),
        *("--out", str(logs)),
    ).stdout
    table = out[out.index("machine:") :].splitlines()[1:]
    names = [re.split(r"  +", line.strip())[0] for line in table]
    lens = importlib.util.find_spec("canopen_lens") is not None
    assert names == [
        "-- CPU seconds (user + system), both sides in the same rounds",
        "python-can LogReader / export --parquet .log, cpu",
        "per round, export --parquet .log",
        "canopen-lens / export --parquet .log, cpu",
        *(["user + system, canopen-lens vs export"] if lens else []),
        "python-can LogReader / decode --summary .log, cpu",
        "python-can LogReader / read only .log, cpu",
        "python-can timed on",
        "check vs decode --summary (.log), cpu",
        "check vs decode --summary (faulty bus .log), cpu",
        "-- wall seconds, the 1-minute load average beside",
        "export --parquet .log frames/s",
        "python-can LogReader / export --parquet .log, wall",
        "decode --summary .log frames/s",
        "read only .log frames/s",
        *(["canopen-lens .log frames/s"] if lens else []),
        "check vs decode --summary (.log), wall",
        "decode -o FILE (.log, no devices) lines/s",
        "decode -o FILE (.log, 16 devices) lines/s",
        "decode -o FILE (.log, no devices, jsonl) lines/s",
        "export --mcap (.log, 16 devices) frames/s",
        "export --rrd (.log, 16 devices) frames/s",
        "-- memory and start-up",
        "peak RSS export --parquet at 0.003M",
        "peak RSS flatness",
        "cananalyze --help",
    ]
    cpu = rf"{NUMBER}x  \({NUMBER} s / {NUMBER} s\)"
    ratio = next(line for line in table if "export --parquet .log, cpu" in line)
    assert re.search(rf"  {cpu} +>= 12x +(ok|BELOW)$", ratio), ratio
    # one round: its own ratio is the best-of ratio (the same two runs)
    per = next(line for line in table if line.strip().startswith("per round"))
    x = r"(\d+\.\d)x"
    got = re.search(rf"{x} median \({x}-{x}, 1 rounds\)", per)
    assert got, per
    assert got[1] == got[2] == got[3] == re.search(x, ratio)[1], (per, ratio)
    lens_row = next(line for line in table if line.startswith("canopen-lens / export"))
    if lens:  # canopen-lens parsed and analysed the same log (a run that read nothing fails)
        assert re.search(rf"  {cpu} +> 1x +(ok|BELOW)$", lens_row), lens_row
        apart = next(line for line in table if "canopen-lens vs export" in line)
        assert re.search(rf"{NUMBER} \+ {NUMBER} s vs {NUMBER} \+ {NUMBER} s", apart), apart
    else:
        assert "not installed" in lens_row
    export = next(line for line in table if line.startswith("export --parquet .log frames/s"))
    assert re.search(rf"cpu {NUMBER} s, load {NUMBER}, {NUMBER} MB\)", export), export
    # 3000 frames and the records between them, as `decode -o` writes them
    text = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log_stem(logs, 3000).with_suffix(".log"))],
        capture_output=True, text=True, check=True, cwd=ROOT,
    ).stdout  # fmt: skip
    assert f"({text.count(chr(10)):,} lines," in out
    # check exits 0 on the healthy bus (a run that exits 1 ends the benchmark), 1 on the
    # faulty one, whose overhead is measured too
    faulty = next(line for line in table if "(faulty bus .log), cpu" in line)
    assert re.search(rf"[+-]{NUMBER} %  \({NUMBER} s vs {NUMBER} s\) +\(reference\) *$", faulty)
    assert not list(logs.glob("tmp*"))  # its temporary outputs are gone


@pytest.mark.slow
def test_bench_decode_against_another_tree(logs, tmp_path):
    """--against with this same checkout: both columns measured, ratios; `--only` keeps the
    run short (every figure's command is listed below, from the same `commands`)."""
    out = _run(
        "bench_decode.py",
        *("--size", "3000", "--formats", ".log", "--repeat", "1", "--only", "export"),
        *("--out", str(logs), "--against", str(ROOT)),
    ).stdout
    best, medians = out[out.index("this / other") :].split("\n\n", 1)
    cell = rf" +{NUMBER}s +{NUMBER}s +{NUMBER}M"  # CPU, wall, peak RSS
    labels = []
    for row in best.splitlines()[2:]:
        m = re.fullmatch(rf"(.+?){cell}{cell} +{NUMBER}x +{NUMBER}x +{NUMBER}x", row)
        assert m, row
        labels.append(m.group(1).strip())
    assert labels == [
        "export --parquet .log",
        "export --mcap (.log, 16 devices)",
        "export --rrd (.log, 16 devices)",
    ]
    # then the medians of the rounds: CPU and wall of each side, and their ratios
    assert medians.startswith("medians of 1 rounds:"), medians
    cell = rf" +{NUMBER}s +{NUMBER}s"
    rows = [r for r in medians.splitlines()[3:] if r.strip()]
    got = [re.fullmatch(rf"(.+?){cell}{cell} +{NUMBER}x +{NUMBER}x", r) for r in rows]
    assert all(got) and [m.group(1).strip() for m in got] == labels, rows
    assert f"other tree (--against): {ROOT}" in out
    spec = importlib.util.spec_from_file_location("bench_decode", BENCH / "bench_decode.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    stem = log_stem(logs, 3000)
    faulty = log_stem(logs, 3000, faults=True).with_suffix(".log")
    every = bench.commands(stem, [".log"], tmp_path, stem.with_suffix(".log"), faulty)
    assert [c[0] for c in every] == [
        "export --parquet .log",
        "decode --summary .log",
        "read only .log",
        "check .log",
        "decode --summary (faulty bus .log)",
        "check (faulty bus .log)",
        "decode -o FILE (.log, no devices)",
        "decode -o FILE (.log, 16 devices)",
        "decode -o FILE (.log, no devices, jsonl)",
        "export --mcap (.log, 16 devices)",
        "export --rrd (.log, 16 devices)",
        "cananalyze --help",
    ]


def test_bench_decode_against_a_folder_without_cananalyze(tmp_path):
    done = subprocess.run(
        [sys.executable, str(BENCH / "bench_decode.py"), "--against", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "no cananalyze package there" in done.stderr


@pytest.mark.slow
def test_bench_floor_table_for_every_format(logs):
    """The library-only CPU of an export (its floor) per input format, beside the export's
    and python-can's CPU, each judged against its target."""
    lines = _run(
        "bench_floor.py", "--size", "3000", "--repeat", "1", "--out", str(logs)
    ).stdout.splitlines()
    assert any(line.startswith("  Parquet encoding of the exported tables:") for line in lines)
    assert any(line.endswith("best of 1); python-can: whole file") for line in lines)
    rows = {line.split()[0]: line for line in lines if line[:1] == "."}
    assert set(rows) == {".log", ".blf", ".asc"}
    for suffix, target in ((".log", 12), (".blf", 8), (".asc", 15)):
        m = re.fullmatch(
            rf"\{suffix} +({NUMBER}) +({NUMBER}) +({NUMBER})  +({NUMBER})x <= 1\.25x (ok|BELOW) +"
            rf"({NUMBER}) +({NUMBER})x >= {target}x (ok|BELOW)",
            rows[suffix],
        )
        assert m, rows[suffix]
        read, floor, export, over = (float(m.group(k)) for k in (1, 3, 5, 7))
        pycan, ahead = float(m.group(10)), float(m.group(12))
        assert 0 <= read < floor and export > 0 and pycan > 0
        # the ratios of the unrounded seconds: within the printed figures' rounding
        assert over == pytest.approx(export / floor, rel=0.05, abs=0.01)
        assert ahead == pytest.approx(pycan / export, rel=0.05, abs=0.06)
        assert (m.group(9) == "ok") == (over <= 1.25) and (m.group(14) == "ok") == (ahead >= target)
    assert not list(logs.glob("tmp*"))  # the exported tables are cleaned up


@pytest.mark.slow
def test_bench_live_keeps_every_frame(tmp_path):
    """live's sinks, the rules and both recordings on a virtual bus: nothing dropped."""
    out = _run(
        "bench_live.py",
        *("--seconds", "1", "--rate", "2000", "--network", str(SAMPLES / "network.toml")),
        *("--check", str(SAMPLES / "rules.yaml"), "--plain"),
        *("--record", str(tmp_path / "r.log"), "--rrd", str(tmp_path / "r.rrd")),
    ).stdout
    got = dict(line.split(None, 1) for line in out.splitlines())
    assert got["sinks"] == "RecordSink, RerunLiveSink, TextWriter, DashboardSink, FindingsSink"
    offered = int(got["offered"].split()[0])
    kept = int(got["kept"].split()[0])
    assert 1500 < offered == kept and got["dropped"] == "0"
    assert re.fullmatch(
        rf"send -> last sink: median {NUMBER} ms, p99 {NUMBER} ms, max {NUMBER} ms",
        got["latency"],
    )
    assert re.fullmatch(r"\d+ frames 0\.5 s after the last send \(drained after\)", got["behind"])
    assert int(got["decoded"].split()[0]) > 0  # the network file's PDOs became signals
    assert int(got["check"].split()[0]) > 0
    recorded = sum(1 for line in (tmp_path / "r.log").read_text().splitlines() if line)
    assert recorded == kept and (tmp_path / "r.rrd").stat().st_size > 0


@pytest.mark.slow
def test_bench_live_decodes_pdos_by_default():
    """No option: nodes 1..16 are the DAT 7014, so PDOs are decoded as users run live;
    --no-devices: frames only, none decoded."""
    for extra, devices in (
        ((), "1..16=dat7014 (default); network none"),
        (("--no-devices",), "none; network none"),
    ):
        out = _run("bench_live.py", "--seconds", "1", "--rate", "2000", *extra).stdout
        got = dict(line.split(None, 1) for line in out.splitlines())
        assert got["devices"] == devices and got["dropped"] == "0"
        decoded = int(got["decoded"].split()[0])
        kept = int(got["kept"].split()[0])
        assert got["decoded"].endswith(f"({kept} frames kept)")
        assert (0 < decoded < kept) if not extra else decoded == 0, got["decoded"]


def test_mem_profile_runs_the_command_and_reports_peaks(tmp_path):
    out = tmp_path / "pq"
    done = _run(
        "mem_profile.py",
        *("--every", "0.01", "export", str(SAMPLES / "faults.log"), "--parquet", str(out), "-q"),
    )
    assert pq.read_table(out / "frames.parquet").num_rows == 933  # the command itself ran
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("peak RSS ")
    peak = int(last.split()[2])
    assert 20 < peak < 2000
    if sys.platform.startswith("linux") and hasattr(ctypes.CDLL(None), "mallinfo2"):
        assert "malloc in use: max" in last  # glibc 2.33+


def test_thread_cpu_medians_per_thread_for_both_trees(tmp_path):
    out = tmp_path / "pq"
    args = ("export", str(SAMPLES / "faults.log"), "--parquet", str(out), *DEVICES[:2], "-q")
    done = _run("thread_cpu.py", "--repeat", "2", "--against", str(ROOT), "--", *args)
    assert pq.read_table(out / "frames.parquet").num_rows == 933  # the command itself ran
    rows = {line.split()[0]: line.split()[1:] for line in done.stdout.splitlines()[3:]}
    for name in ("main", "cananalyze-reader", "table-writer", "process"):
        assert name in rows, done.stdout
    main, other, ratio = rows["main"]
    assert re.fullmatch(NUMBER + "s", main) and re.fullmatch(NUMBER + "s", other)
    assert 0 < float(main[:-1]) <= float(rows["process"][-3][:-1]) + 0.05
    assert re.fullmatch(NUMBER + "x", ratio)


def test_arrow_column_waits_for_a_whole_pyarrow(monkeypatch):
    """The sampler runs while the CLI imports pyarrow: a module without its functions yet
    is no figure, not an error that stops the sampling (it did, on a 50M-frame run)."""
    import types

    sys.path.insert(0, str(BENCH))
    try:
        import mem_profile
    finally:
        sys.path.remove(str(BENCH))
    monkeypatch.setitem(sys.modules, "pyarrow", types.ModuleType("pyarrow"))  # mid-import
    assert mem_profile._arrow_mb() is None
    monkeypatch.delitem(sys.modules, "pyarrow")
    assert mem_profile._arrow_mb() is None
    whole = types.ModuleType("pyarrow")
    whole.total_allocated_bytes = lambda: 5 << 20
    monkeypatch.setitem(sys.modules, "pyarrow", whole)
    assert mem_profile._arrow_mb() == 5


@pytest.mark.slow
def test_bench_report_prints_cpu_wall_and_page_size(logs):
    """Both buses (the faulty one generated beside the healthy one): check's and report's
    figures, their CPU ratio and the page's size, which is the file's."""
    out = _run("bench_report.py", "3000", "1", "--out", str(logs), "--bus", "both")
    lines = out.stdout.splitlines()
    assert len(lines) == 8
    for k, (bus, log) in enumerate(
        (("healthy", log_stem(logs, 3000)), ("faulty", log_stem(logs, 3000, faults=True)))
    ):
        head, check, report, tail = lines[4 * k : 4 * k + 4]
        assert re.fullmatch(
            rf"{bus} bus: {log.name}\.log, 3000 frames, {NUMBER} s of log, best of 1", head
        )
        for line, name in ((check, "check"), (report, "report")):
            assert re.fullmatch(
                rf" +{name} +CPU +{NUMBER} s +wall +{NUMBER} s +peak RSS +{NUMBER} MB", line
            )
        ratio, size = re.fullmatch(
            rf" +report/check CPU ({NUMBER}) +page ({NUMBER}) MB", tail
        ).group(1, 3)
        assert float(ratio) > 0
        page = logs / f"report_this_{log.name}.html"
        assert 0.5 < float(size) < 3 and page.stat().st_size == pytest.approx(
            float(size) * 1e6, abs=1e4
        )


@pytest.mark.slow
def test_bench_live_serves_foxglove_without_drops():
    """--foxglove: the server's client (another process) gets every frame the sinks kept."""
    pytest.importorskip("foxglove")
    pytest.importorskip("websockets")
    out = _run(
        "bench_live.py",
        *("--seconds", "1", "--rate", "2000", "--network", str(SAMPLES / "network.toml")),
        "--foxglove",
    ).stdout
    got = dict(line.split(None, 1) for line in out.splitlines())
    assert got["sinks"] == "FoxgloveSink, DashboardSink"
    kept = int(got["kept"].split()[0])
    assert got["dropped"] == "0" and kept > 1500
    m = re.fullmatch(
        r"(\d+) frames and (\d+) messages on (\d+) topics received by the client "
        rf"\((\d+) sent; the client, another process, {NUMBER} s CPU\)",
        got["foxglove"],
    )
    assert m and int(m.group(1)) == kept and m.group(2) == m.group(4)
    assert int(m.group(3)) > 2  # frames, events and the network file's PDO topics
    assert re.fullmatch(rf"{NUMBER} s user\+system beside {NUMBER} s wall", got["cpu"])
    assert re.fullmatch(rf"{NUMBER} {NUMBER} {NUMBER} \(1, 5, 15 min, at the end\)", got["load"])


def test_bench_dbc_compares_with_cantools():
    out = _run("bench_dbc.py", "--frames", "3000", "--repeat", "1").stdout
    for side in ("cananalyze", "cantools"):
        assert re.search(rf"  {side} +wall +{NUMBER} s  cpu +{NUMBER} s +[\d,]+ frames/s", out)
    assert re.search(
        rf"cantools / cananalyze: wall {NUMBER}x  cpu {NUMBER}x  \(values equal\)", out
    )


def test_bench_pcap_reads_every_frame():
    out = _run("bench_pcap.py", "--frames", "3000", "--repeat", "1", "--scapy-frames", "500").stdout
    assert "read 3,000 frames (scapy: the first 500)" in out
    for side, count in (("pcap", "3,000"), ("candump", "3,000"), ("scapy rdpcap", "500")):
        assert re.search(rf"  {side} +wall +{NUMBER} s  cpu +{NUMBER} s .*\({count} frames\)", out)


@pytest.mark.slow  # a benchmark run end to end
def test_bench_mf4_reads_every_frame(tmp_path):
    pytest.importorskip("asammdf")
    out = _run("bench_mf4.py", "3000", "--rounds", "1", "--out", str(tmp_path)).stdout
    assert "3,000 frames generated, median of 1 rounds" in out
    for name in ("candump", "blf", "mf4", "mf4 deflate"):
        assert re.search(rf"^{name} +\d+ +3,000 +{NUMBER} +{NUMBER} +[\d,]+ +[\d,]+$", out, re.M)


@pytest.mark.slow
def test_bench_precision_table_per_rule_and_per_1000_frames():
    """The samples as the "real" folder, this checkout against itself: every log listed
    with its findings in both columns, per rule counts and rates, CPU beside wall."""
    lines = _run(
        "bench_precision.py", "--data", str(SAMPLES), "--no-stack", "--against", str(ROOT)
    ).stdout.splitlines()
    assert lines[0].split() == ["log", "frames", "this", "other", "(findings)"]
    faults = next(line for line in lines if line.startswith("faults.log"))
    _, frames, this, other = faults.split()
    assert int(frames) > 100 and int(this) == int(other) > 0
    rate = rf" +\d+ \( *{NUMBER}\)"
    per_rule = [line for line in lines if re.fullmatch(rf"  \w+{rate}{rate}", line)]
    assert any(line.split()[0] == "all" for line in per_rule) and len(per_rule) >= 3
    for name in ("this", "other"):
        assert any(
            re.fullmatch(rf"{name}: CPU {NUMBER} s, wall {NUMBER} s \(.+\)", x) for x in lines
        )


@pytest.mark.slow
def test_fuzz_campaign_counts_every_category(tmp_path):
    done = _run("fuzz_campaign.py", "--seconds", "6", "--seed", "5", "--out", str(tmp_path))
    lines = done.stdout.splitlines()
    assert re.match(rf"fuzz campaign: seed 5, {NUMBER} s wall, {NUMBER} s CPU", lines[0])
    assert lines[1].split() == ["kind", "cases", "crash", "hang", "memory", "lost", "leftover"]
    total = next(line.split() for line in lines if line.startswith("total"))
    assert int(total[1]) > 0 and all(x.isdigit() for x in total[1:])
    assert any(line.startswith("distinct failures:") for line in lines)
