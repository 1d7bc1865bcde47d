"""The columnar JSONL writer (outputs/jsonl/columns) prints exactly what the per-row
writer prints: every input is written both ways, whole and through filters."""

from __future__ import annotations

import io
import json
import sys

import numpy as np
import pytest
from conftest import ROOT, SAMPLES, generated_log, real_file
from exported import DEVICES
from helpers.broken_disk import broken_text_stream

from cananalyze.cli.common import options
from cananalyze.cli.main import build_parser
from cananalyze.core.records import SignalBlock
from cananalyze.formats.source import open_log
from cananalyze.outputs.jsonl import columns as jsonl_columns
from cananalyze.outputs.jsonl.rows import JsonlWriter
from cananalyze.pipeline import build_decoder

sys.path.insert(0, str(ROOT / "benchmarks"))


def _decode(argv: list[str], fb=None, step: int = 7000):
    args = build_parser().parse_args(["decode", *argv])
    dec = build_decoder(options(args))
    if fb is None:
        out = [dec.decode(b) for b in open_log(args.log).batches()]
    else:
        out = [dec.decode(fb.take(slice(s, s + step))) for s in range(0, len(fb), step)]
    out.append(dec.finish())
    return out


def _masks(batch):
    n = len(batch)
    yield None
    yield np.isin(batch.node, [3, 5, 10])
    yield np.isin(batch.service, [4, 5, 7])
    yield np.random.default_rng(n).random(n) < 0.3


def _both(batches, monkeypatch) -> int:
    """Write each batch with each mask both ways; the texts must be equal."""
    lines = 0
    for k in range(4):
        outs = []
        for columnar in (True, False):
            with monkeypatch.context() as m:
                if not columnar:
                    m.setattr(jsonl_columns, "render", lambda batch, mask: None)
                out = io.StringIO()
                writer = JsonlWriter(out)
                for b in batches:
                    writer.write(b, list(_masks(b))[k] if len(b) else None)
                outs.append(out.getvalue())
        pairs = enumerate(zip(*map(str.splitlines, outs), strict=False))
        first = next((f"line {j}: {a} != {b}" for j, (a, b) in pairs if a != b), "length")
        assert outs[0] == outs[1], first
        lines += outs[0].count("\n")
    return lines


@pytest.mark.parametrize(
    "argv",
    [
        [str(SAMPLES / "demo.log")],
        [str(SAMPLES / "faults.blf"), "--network", str(SAMPLES / "network.toml")],
        [str(SAMPLES / "commissioning.log"), "--network", str(SAMPLES / "network.toml")],
    ],
)
def test_samples(argv, monkeypatch):
    assert _both(_decode(argv), monkeypatch) > 100


@pytest.mark.parametrize(
    "rel",
    [
        "hilch__canopen-message-interpreter/pcan3.trc",
        "isPointless__Sevcon/can_180209_154604.txt",
        "nigel-bruce-khan__ros_canopen-tmcm-1636/candump.txt",
    ],
)
@pytest.mark.slow
def test_real_logs(rel, monkeypatch):
    assert _both(_decode([str(real_file(rel))]), monkeypatch) > 10


def test_pdo_signals_of_an_eds(monkeypatch):
    eds = real_file("jclinton830__canopen_test/roboteq_motor_controllers_v80.eds")
    batches = _decode(
        [str(real_file("jclinton830__canopen_test/candump.txt")), "--eds", f"12={eds}"]
    )
    assert any(b.signals for b in batches)
    assert _both(batches, monkeypatch) > 10


def test_benchmark_mix_with_devices(monkeypatch):
    from generate import generate

    devices = [a for k in range(1, 17) for a in ("--device", f"{k}=dat7014")]
    batches = _decode(["x.log", *devices], generate(20_000, seed=4))
    assert any(b.signals for b in batches)
    assert _both(batches, monkeypatch) > 20_000


def test_signal_values_python_words_its_own_way(monkeypatch):
    """Whole numbers ("2.0"), exponents both ways, NaN and inf (null), ints, bools and
    a uint64 column beyond int64 (the block's rows then go row by row)."""
    batches = _decode([str(SAMPLES / "demo.log")])
    batch = next(b for b in batches if len(b) > 20)
    rows = np.arange(0, 16, dtype=np.int64)
    floats = np.array(
        [2.0, -0.0, 1e-5, 1e16, 1.5e-4, 123456789012345.6, np.nan, np.inf, -np.inf, 0.1]
        + [1 / 3, 1e15, 5e-324, 9999999999999998.0, -649.0, 1e300]
    )
    batch.signals = [
        SignalBlock(rows, 9, "tpdo1", 0x189, {"f": floats, "i": -rows, "b": rows % 2 == 0}, {}),
        SignalBlock(
            rows + 20, 9, "tpdo2", 0x289, {"u": np.full(16, 2**64 - 1, np.uint64)}, {"u": "V"}
        ),
    ]
    batch.service[rows] = 5  # TPDO rows without notes
    batch.service[rows + 20] = 5
    for r in (*rows.tolist(), *(rows + 20).tolist()):
        dict.pop(batch.notes, r, None)
    batch._lazy = None
    assert _both([batch], monkeypatch) >= 32
    line = JsonlWriter(io.StringIO())
    line.write(batch)
    first = json.loads(line.out.getvalue().splitlines()[0])
    assert first["signals"] == {"f": 2.0, "i": 0, "b": True}


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_float_text_equals_repr_or_null(compiled, monkeypatch):
    """Python's repr is the definition, on both paths: the compiled one copies Arrow's
    text and mends it, the numpy one mends it in passes."""
    if not compiled:
        monkeypatch.setattr(jsonl_columns, "C", None)
    elif getattr(jsonl_columns.C, "float_repr", None) is None:
        pytest.skip("compiled helper not in use")
    rng = np.random.default_rng(9)
    v = np.sign(rng.normal(size=20000)) * 10.0 ** rng.uniform(-8, 20, 20000)
    stamps = 1767225600 + np.cumsum(rng.integers(1, 5000, 5000)) / 1e6  # candump -l times
    rel = np.cumsum(rng.integers(1, 90, 5000)) / 1e6  # relative times from 1 us (5e-06)
    tenths = rng.integers(0, 2**32 * 10, 3000) / 10  # whole and tenths of seconds
    top = np.array([4294967295.999999, 4294967295.5, 4294967296.5, 4294967296.000001])
    stamps = np.concatenate([stamps, -stamps[:100], rel, tenths, top, rel[:50] / 10])
    edges = [0.0, -0.0, np.nan, -np.nan, np.inf, -np.inf, 1e-4, 9.999999999999999e-05, 1e16]
    edges += [9999999999999998.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308]
    edges += [0.1, 1 / 3, -123456789.0, 0.00012345678901234567, 2.0**53, 2.0**53 + 2]
    v = np.concatenate([v, np.round(v), stamps, edges, rng.random(3000) * 1e-4])
    got = [bytes(row[row != 0]).decode() for row in jsonl_columns._floats(v)]
    want = [repr(x) if np.isfinite(x) else "null" for x in v.tolist()]
    assert got == want
    assert jsonl_columns._floats(np.zeros(0)).shape[0] == 0


def test_records_of_rows_not_shown_come_last(monkeypatch):
    batches = _decode([str(SAMPLES / "faults.log"), "--network", str(SAMPLES / "network.toml")])
    for b in batches:
        if len(b):
            b.add_record(-1, {"kind": "finding", "rule": "x", "message": "end of batch"})
            b.add_record(0, {"kind": "finding", "rule": "y", "message": "first row"})
    assert _both(batches, monkeypatch) > 100


def test_the_cli_writes_it(tmp_path):
    out = tmp_path / "o.jsonl"
    args = build_parser().parse_args(
        ["decode", str(SAMPLES / "faults.log"), "--format", "jsonl", "-o", str(out)]
    )
    assert args.func(args) in (0, None, 1)
    lines = out.read_text().splitlines()
    assert len(lines) > 100 and all(json.loads(line)["kind"] for line in lines)


def test_sdo_pairs_from_columns(tmp_path, monkeypatch):
    """The fast pairs' frames (uploads, downloads with and without a size, an abort) get
    their fields from columns, per command byte, and print as the per-row writer prints."""
    from cananalyze.outputs.jsonl import sdo as sdo_jsonl
    from tests.outputs.test_sdo_text import PAIRS, _log

    taken = []
    group = sdo_jsonl._group

    def counting(*args):
        block = group(*args)
        taken.append(0 if block is None else len(block))
        return block

    monkeypatch.setattr(sdo_jsonl, "_group", counting)
    batches = _decode([str(_log(tmp_path, PAIRS)), "--device", "1=dat7014"])
    assert _both(batches, monkeypatch) >= 2 * len(PAIRS)
    assert sum(taken) >= 2 * (len(PAIRS) - 1)  # every frame but the abort's pair


def test_background_jsonl_writer_raises_in_close():
    """Written by a worker thread (as `decode -o` does): a failing disk is raised by
    close(), not lost in the thread."""

    writer = JsonlWriter(broken_text_stream(), background=True)
    with pytest.raises(OSError, match="disk full"):
        for b in _decode([str(SAMPLES / "demo.log")]):
            writer.write(b)
        writer.close()


def test_background_jsonl_writer_writes_the_same(tmp_path):
    batches = _decode([str(SAMPLES / "faults.log"), "--network", str(SAMPLES / "network.toml")])
    texts = []
    for background in (False, True):
        path = tmp_path / f"{background}.jsonl"
        with open(path, "w", encoding="utf-8") as out:
            writer = JsonlWriter(out, background=background)
            for b in batches:
                writer.write(b)
            writer.close()
        texts.append(path.read_bytes())
    assert texts[0] == texts[1] and texts[0].count(b"\n") > 100


def test_cia402_signal_words_from_columns(monkeypatch):
    """The ZeroErr drive's statuswords and controlwords in words: columns = per row."""
    log = real_file("SeonilChoi__CANOPEN-SDK/log2.txt")
    batches = _decode([str(log), "--device", "11=cia402"], step=300)
    assert any(sb.words for b in batches for sb in b.signals)
    assert _both(batches, monkeypatch) > 1000


@pytest.mark.parametrize(
    "argv",
    [
        ["faults.log", "--network", "network.toml"],
        ["commissioning.log", "--network", "network.toml"],
        ["generated"],
    ],
    ids=["faults", "commissioning", "generated"],
)
def test_sdo_record_lines_are_the_records_dumped(argv, tmp_path):
    """Each transfer's JSON line from the columns is `dumps` of its record dict."""
    from cananalyze.outputs.jsonl.encode import dumps
    from cananalyze.outputs.jsonl.sdo import record_lines

    args = [str(SAMPLES / a) if a.endswith((".log", ".toml")) else a for a in argv]
    if args == ["generated"]:  # 16 DAT 7014 modules: named objects, values decoded
        args = [str(generated_log(tmp_path, 30000))]
        args += [a for n, d in DEVICES.items() for a in ("--device", f"{n}={d}")]
    fast = 0
    for b in _decode(args):
        fields = b.records.fields()
        fast += len(fields) - len(fields.held)
        want = [(dumps(rec) + "\n").encode() for _, rec in b.records]
        assert record_lines(fields) == want
    assert fast > 0


def test_sdo_record_lines_word_every_kind_of_value_as_dumps():
    """Values the fast path can hold (ints, floats with -0.0 and NaN, text needing
    escapes, bytes, words) and a NaN latency: each line is the record dumped."""
    from cananalyze.outputs.jsonl.encode import dumps
    from cananalyze.outputs.jsonl.sdo import record_lines

    batches = _decode([str(SAMPLES / "faults.log"), "--network", str(SAMPLES / "network.toml")])
    fields = next(b.records.fields() for b in batches if len(b.records.fields()) > 12)
    kinds = [0, -0.0, 0.0, 2.5, float("nan"), 'é"\\\n\x01', "abc", b"\x01\xff", np.int64(-3)]
    kinds += [np.float32(0.1), True, None, {"state": "operational", "bits": [1, 2]}]
    values = np.empty(len(fields), object)
    values[:] = [kinds[j % len(kinds)] for j in range(len(fields))]
    fields.arrays["value"] = values
    fields.arrays.pop("value_int", None)
    words = np.empty(len(fields), object)
    words[:] = [{"x": j} if j % 3 == 0 else None for j in range(len(fields))]
    fields.arrays["words"] = words
    fields.arrays["latency_ms"] = fields.arrays["latency_ms"].copy()
    fields.arrays["latency_ms"][1] = np.nan
    want = [(dumps(fields.record(j)) + "\n").encode() for j in range(len(fields))]
    assert record_lines(fields) == want
    assert b'"latency_ms":NaN' in b"".join(want) and b'"value":-0.0' in b"".join(want)
