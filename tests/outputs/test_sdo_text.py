"""The SDO fast path's text lines built from columns (decode/sdo/roles, outputs/text/sdo)
are the ones the tracker and `format_record` write, and a batch renders the same with and
without them.

The pairs are crafted to reach every branch: uploads and downloads (with and without
a size), values of one digit, wide and negative, an object the profile does not
know (data only), a server abort, an answer stamped before its request (negative
latency), a text value (the whole batch then goes record by record), and rows that
hold other records too.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLES, real_file

from cananalyze.core.columns import bytecols
from cananalyze.decode.sdo.processor import SdoProcessor
from cananalyze.decode.sdo.roles import pair_roles
from cananalyze.formats.source import read_all
from cananalyze.outputs.text import writer as text_module
from cananalyze.outputs.text.records import format_record
from cananalyze.outputs.text.sdo import fast_pairs, record_lines
from cananalyze.outputs.text.writer import TextWriter
from cananalyze.pipeline import Options, build_decoder

# (request, answer) payloads on node 1 (a DAT 7014) unless the id says otherwise
PAIRS = [
    ("601", "4018100100000000", "581", "4318100178563412"),  # u32 0x12345678: wide
    ("601", "4017100000000000", "581", "4B17100009000000"),  # u16 9: no hex
    ("601", "4017100000000000", "581", "4B1710000A000000"),  # u16 10: with hex
    ("601", "2B171000E8030000", "581", "6017100000000000"),  # download, 2 bytes named
    ("601", "2217100001000000", "581", "6017100000000000"),  # download, size not named
    ("601", "40FF2F0100000000", "581", "43FF2F01DEADBEEF"),  # unknown object: data only
    ("601", "4001640100000000", "581", "4B016401FEFF0000"),  # i16 -2
    ("601", "4001640200000000", "581", "4B01640218FC0000"),  # i16 -1000: wide, negative
    ("601", "4018100500000000", "581", "8018100511000906"),  # abort
    ("602", "4000200000000000", "582", "4300200091010000"),  # no profile, a maker's object
    ("602", "2300200001020304", "582", "6000200000000000"),
]
STRING = ("601", "4008100000000000", "581", "4308100044415420")  # "DAT ": a text value


def _log(tmp_path: Path, pairs, back: bool = False) -> Path:
    lines, t = [], 100.0
    for k, (req_id, req, resp_id, resp) in enumerate(pairs):
        t_resp = t - 0.1 if back and k == 3 else t + 0.0123
        lines.append(f"({t:.6f}) can0 {req_id}#{req}")
        lines.append(f"({t_resp:.6f}) can0 {resp_id}#{resp}")
        t += 0.05
    lines.append(f"({t:.6f}) can0 080#")  # a SYNC: a row no pair covers
    path = tmp_path / "pairs.log"
    path.write_text("\n".join(lines) + "\n")
    return path


def _batch(log: Path, *devices: str, fast: bool = True):
    """The log decoded as one batch; `fast=False`: every SDO frame through the tracker."""
    pairs = (d.split("=") for d in devices)
    decoder = build_decoder(Options(devices={int(n): k for n, k in pairs}))
    for proc in decoder.processors:
        if isinstance(proc, SdoProcessor):
            proc.fast = fast
    return decoder.decode(read_all(log))


def _assert_pair_texts(batch, log: Path) -> int:
    pairs = fast_pairs(batch)
    assert pairs is not None
    fields, fast = pairs
    req, resp = fast.cols.req_row, fast.cols.row
    req_role, resp_role = pair_roles(batch.frames, fields, req, resp, b"\n")
    m = len(fields)
    tracked = _batch(log, "1=dat7014", fast=False).notes  # the tracker's words for each frame
    for matrix, rows in ((req_role, req), (resp_role, resp)):
        blob, ends = bytecols.compact([matrix], m, with_ends=True)
        want = ["SDO " + tracked[r]["role"] + "\n" for r in rows.tolist()]
        assert bytecols.split_rows(blob, ends) == want
    # the notes dict, once read, holds the tracker's notes for those frames
    for r in np.concatenate((req, resp)).tolist():
        assert batch.notes[r] == tracked[r]
    # every record of the batch (the tracker's too), as format_record words its dict
    every = batch.records.fields()
    want = [("    └─ " + format_record(r) + "\n").encode() for _, r in batch.records]
    assert record_lines(every) == want
    assert record_lines(fields) == [
        ("    └─ " + format_record(r) + "\n").encode() for r in fields.records()
    ]
    return m


@pytest.mark.parametrize("back", [False, True])
def test_crafted_pairs_as_the_per_pair_texts(tmp_path, back):
    log = _log(tmp_path, PAIRS, back)
    batch = _batch(log, "1=dat7014")
    fields = fast_pairs(batch)[0]
    assert _assert_pair_texts(batch, log) == len(PAIRS)
    assert "value_int" in fields.arrays and len(fields.held) == 1
    lines = record_lines(fields)
    assert b"0x1018:01 Vendor-ID expedited -> ok: 305419896 (0x12345678) (4 bytes)" in lines[0]
    assert b": -1000 (0xFFFFFFFFFFFFFC18) (2 bytes)" in lines[7]
    assert b"node 2 SDO read 0x2000:00 expedited -> ok: data 91010000 (4 bytes)" in lines[9]
    assert (b", latency -100.0 ms" in lines[3]) == back


def test_a_text_value_sends_the_batch_record_by_record(tmp_path):
    log = _log(tmp_path, [*PAIRS, STRING])
    batch = _batch(log, "1=dat7014")
    assert "value_int" not in fast_pairs(batch)[0].arrays
    assert _assert_pair_texts(batch, log) == len(PAIRS) + 1


def _render(batch, pairs: bool, color: bool, monkeypatch) -> str:
    with monkeypatch.context() as m:
        if not pairs:
            m.setattr(text_module, "fast_pairs", lambda batch: None)
        out = io.StringIO()
        TextWriter(out, color=color).write(batch)
        return out.getvalue()


@pytest.mark.parametrize("color", [False, True])
def test_rows_with_other_records_too(tmp_path, monkeypatch, color):
    """Records added to an answer's row, a request's row and no row: each row's records
    keep their order, and the notes of the pairs are still unwritten when rendered (also
    with another row's note written)."""
    batches = [_batch(_log(tmp_path, PAIRS), "1=dat7014") for _ in range(2)]
    for batch in batches:
        fast = batch.records.fast_part()
        batch.add_record(
            int(fast.cols.row[0]), {"kind": "finding", "rule": "r1", "message": "late"}
        )
        batch.add_record(
            int(fast.cols.req_row[1]), {"kind": "finding", "rule": "r2", "message": "x"}
        )
        batch.add_record(-1, {"kind": "finding", "rule": "r3", "message": "end"})
        batch.notes[len(batch) - 1] = {"noted": "by hand"}  # a written note beside them
    assert fast_pairs(batches[0]) is not None
    got = _render(batches[0], True, color, monkeypatch)
    assert batches[0].notes.pending_rows() is not None  # rendered without writing them
    want = _render(batches[1], False, color, monkeypatch)
    assert got == want
    assert "late" in got and "end" in got


@pytest.mark.parametrize(
    "log, devices",
    [
        (SAMPLES / "commissioning.log", ()),
        (SAMPLES / "faults.log", ()),
        ("hilch__canopen-message-interpreter/pcan3.trc", ()),
        ("hilch__canopen-message-interpreter/pcan1.trc", ()),
    ],
)
def test_whole_logs_render_the_same(monkeypatch, log, devices):
    path = log if isinstance(log, Path) else real_file(log)
    got, want = (
        _render(_batch(path, *devices), pairs, False, monkeypatch) for pairs in (True, False)
    )
    assert got == want
    assert got.count("└─") > 20


def test_notes_read_before_rendering_take_the_other_path(tmp_path):
    """Once anyone has read the notes (here: all of them), the pairs are not taken apart."""
    batch = _batch(_log(tmp_path, PAIRS), "1=dat7014")
    assert len(batch.notes) > 0
    assert fast_pairs(batch) is None
    cols = batch.records.fast_part().cols
    assert np.all(cols.req_row < cols.row)
