"""One text per fact: the columnar builders say what their scalar twins say, a short
frame's verdict is the same in text and JSONL, and an object is written 0xIIII:SS in
every text (frame lines, transaction lines, findings, events)."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, real_file

from cananalyze.core.columns import bytecols
from cananalyze.protocol import emcy, nmt, sdo
from cananalyze.protocol.fields import annotation, frame_fields
from cananalyze.protocol.services import Service


def test_emcy_text_columns_equal_the_scalar_text():
    rng = np.random.default_rng(3)
    n = 20000
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    data[: n // 4, :2] = 0  # error resets
    data[n // 4 : n // 2, 1] = rng.choice([0x10, 0x21, 0x42, 0x81, 0x82, 0xFF], n // 4)
    dlc = rng.integers(0, 9, n).astype(np.uint8)
    got = bytecols.joined_rows(emcy.text_columns(data, dlc), n)
    want = [emcy.annotation(emcy.fields(bytes(data[i, : dlc[i]]))) for i in range(n)]
    assert got == want


def test_emcy_head_block_equals_error_text_for_every_code():
    """The heads built by lookup tables say what `error_text` says, code by code."""
    codes = np.arange(1 << 16, dtype=np.int64)
    got = bytecols.joined_rows([emcy._head_block(codes)], len(codes))
    assert got == [f"EMCY {emcy.error_text(c)}; " for c in codes.tolist()]


def test_object_columns_equal_object_text():
    rng = np.random.default_rng(4)
    index = rng.integers(0, 1 << 16, 5000)
    sub = rng.integers(0, 256, 5000)
    got = [bytes(row).decode() for row in sdo.object_columns(index, sub)]
    assert got == [sdo.object_text(i, s) for i, s in zip(index.tolist(), sub.tolist(), strict=True)]
    assert sdo.object_text(0x2010, 8) == "0x2010:08" and sdo.object_text(0x1018) == "0x1018"


def test_register_for_sets_generic_and_the_class_bit():
    assert emcy.register_for(0) == 0
    assert emcy.register_names(emcy.register_for(0x8130)) == ["generic", "communication"]
    assert emcy.register_names(emcy.register_for(0x3210)) == ["generic", "voltage"]
    assert emcy.register_names(emcy.register_for(0x6100)) == ["generic"]


def _cli(*args: str) -> str:
    out = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, cwd=ROOT, check=True
    )
    return out.stdout.decode()


SHORT = {  # short frames and the word their text and JSONL both give
    "000#01": nmt.MALFORMED,
    "000#": nmt.MALFORMED,
    "085#1081": emcy.MALFORMED,
    "085#": emcy.MALFORMED,
    "100#0011223344": "malformed",
}


def test_short_frames_say_malformed_in_text_and_jsonl(tmp_path):
    log = tmp_path / "short.log"
    frames = [*SHORT, "000#0105", "085#1081010000000000", "100#00112233AABB"]
    log.write_text("".join(f"({1.0 + k / 10:.6f}) can0 {f}\n" for k, f in enumerate(frames)))
    text = _cli("decode", str(log), "--no-color").splitlines()
    lines = [json.loads(x) for x in _cli("decode", str(log), "--format", "jsonl").splitlines()]
    assert len(text) == len(lines) == len(frames)
    for k, problem in enumerate(SHORT.values()):
        assert lines[k]["problem"] == problem
        assert text[k].endswith(f"({problem})")
    assert not any("problem" in rec for rec in lines[len(SHORT) :])
    # the scalar route says the same
    for raw, problem in SHORT.items():
        cob, data = raw.split("#")
        service = {"000": Service.NMT, "085": Service.EMCY, "100": Service.TIME}[cob]
        fields = frame_fields(service, bytes.fromhex(data))
        assert fields["problem"] == problem
        assert annotation(service, 5, 0, fields).endswith(f"({problem})")


_OBJECT = re.compile(r"0x[0-9A-F]{4}:(\w+)")


def _subindexes(text: str) -> set[str]:
    return set(_OBJECT.findall(text))


@pytest.mark.slow
def test_objects_written_with_a_two_digit_hex_subindex_everywhere(tmp_path):
    """pcan3.trc reads 0x2010:08 and 0x205B:01 (aborted): the frame lines, their
    transaction lines, the findings and the events table all write the sub-index so."""
    trc = str(real_file("hilch__canopen-message-interpreter/pcan3.trc"))
    text = _cli("decode", trc, "--no-color", "--check")
    frame = [ln for ln in text.splitlines() if "sdo_request" in ln and "0x2010:" in ln]
    record = [ln for ln in text.splitlines() if "└─ node" in ln and "0x2010:" in ln]
    finding = [ln for ln in text.splitlines() if "ERROR sdo:" in ln]
    assert frame and record and finding
    assert "SDO upload request 0x2010:08" in text and "SDO read 0x2010:08" in text
    assert "SDO upload 0x205B:01 abort" in text
    jsonl = _cli("decode", trc, "--format", "jsonl")
    _cli("export", trc, "-q", "--csv", str(tmp_path / "csv"))
    with open(tmp_path / "csv" / "events.csv", newline="") as f:
        events = " ".join(row["message"] for row in csv.DictReader(f))
    assert "SDO upload 0x2010:08" in events
    for where in (text, jsonl, events):
        subs = _subindexes(where)
        assert subs and all(re.fullmatch(r"[0-9A-F]{2}", s) for s in subs), sorted(subs)[:5]
