"""An 11-bit frame cannot carry an identifier above 0x7FF: such a frame is never CANopen.

`FFF#0105` looks like "NMT start node 5" to a table lookup that ignores the high
bits. The candump reader refuses the line (as the ASC, TRC and other text readers
refuse theirs), with a warning naming the file and line; a frame that arrives
anyway (python-can's readers, BLF files, a live bus) is classified `other`. The
CLI cases run with and without the compiled helper in every suite run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import can
import numpy as np
import pytest
from conftest import ROOT

from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FrameBatch
from cananalyze.protocol.cobid import NO_NODE, CobClassifier
from cananalyze.protocol.services import SERVICE_NAMES

LOG = (
    b"(1767225600.000000) can0 FFF#0105\n"
    b"(1767225600.100000) can0 000#0105\n"
    b"(1767225600.200000) can0 805#0105\n"
    b"  can0  F05   [1]  05\n"
)


def _batch(rows: list[tuple[int, int, bytes]]) -> FrameBatch:
    b = FrameBatch.allocate(len(rows))
    for i, (can_id, flags, data) in enumerate(rows):
        b.can_id[i], b.flags[i], b.dlc[i] = can_id, flags, len(data)
        b.data[i, : len(data)] = np.frombuffer(data, np.uint8)
    return b


def test_the_classifier_takes_only_ids_that_fit_11_bits() -> None:
    rows = [
        (0x000, 0, b"\x01\x05"),  # NMT start node 5
        (0x705, 0, b"\x05"),  # heartbeat, node 5
        (0x7FF, 0, b""),  # the largest 11-bit id: not in the predefined set
        (0xFFF, 0, b"\x01\x05"),  # low 11 bits 0x7FF; read as index 0 it was NMT
        (0x800, 0, b"\x01\x05"),  # low 11 bits 0x000
        (0xF05, 0, b"\x05"),  # low 11 bits 0x705
        (0x1FFFFFFF, 0, b"\x05"),
        (0x705, FLAG_EXT, b"\x05"),
        (0x080, FLAG_ERR, b""),
    ]
    got = CobClassifier().classify(_batch(rows))
    names = [SERVICE_NAMES[s] for s in got.service.tolist()]
    assert names == ["nmt", "heartbeat", "other", "other", "other", "other", "other", "other"] + [
        "error_frame"
    ]
    assert got.node.tolist() == [NO_NODE, 5] + [NO_NODE] * 7
    assert got.pdo.tolist() == [0] * 9


def _decode(path: Path, pure: str, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, CANANALYZE_PURE=pure)
    return subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(path), "--no-color", *args],
        capture_output=True,
        cwd=ROOT,
        env=env,
        text=True,
    )


@pytest.mark.parametrize("pure", ["", "1"])
def test_candump_refuses_3_digit_ids_above_7ff(tmp_path: Path, pure: str) -> None:
    path = tmp_path / "wide.log"
    path.write_bytes(LOG)
    out = _decode(path, pure)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert len(lines) == 1 and lines[0].endswith("NMT start node 5")  # line 2 only
    for n, ident in ((1, "FFF"), (3, "805"), (4, "F05")):
        assert f"{path}:line {n}: identifier '{ident}' is above 7FF" in out.stderr
    assert "3 unreadable lines" in out.stderr
    jsonl = _decode(path, pure, "--format", "jsonl")
    assert jsonl.returncode == 0, jsonl.stderr
    records = [json.loads(line) for line in jsonl.stdout.splitlines()]
    assert [(r["can_id"], r["service"]) for r in records] == [(0, "nmt")]
    strict = _decode(path, pure, "--strict")
    assert strict.returncode == 2 and "line 1" in strict.stderr
    assert "Traceback" not in strict.stderr and strict.stdout == ""


@pytest.mark.parametrize("pure", ["", "1"])
def test_frames_from_other_readers_are_other(tmp_path: Path, pure: str) -> None:
    """python-can keeps such a frame (its candump and BLF readers), so it reaches the
    classifier: `other`, with no node."""
    path = tmp_path / "wide.log"
    path.write_bytes(LOG[: LOG.index(b"  can0")])
    out = _decode(path, pure, "--format", "jsonl", "--input-format", "pycan")
    assert out.returncode == 0, out.stderr
    records = [json.loads(line) for line in out.stdout.splitlines()]
    assert [(r["can_id"], r["service"], r["node"]) for r in records] == [
        (0xFFF, "other", None),
        (0x000, "nmt", None),
        (0x805, "other", None),
    ]
    blf = tmp_path / "wide.blf"
    with can.BLFWriter(str(blf)) as w:
        for t, ident in ((1.0, 0xFFF), (1.1, 0x000), (1.2, 0xF05)):
            data = b"\x05" if ident == 0xF05 else b"\x01\x05"
            w.on_message_received(
                can.Message(timestamp=t, arbitration_id=ident, is_extended_id=False, data=data)
            )
    out = _decode(blf, pure, "--format", "jsonl")
    assert out.returncode == 0, out.stderr
    records = [json.loads(line) for line in out.stdout.splitlines()]
    assert [(r["can_id"], r["service"]) for r in records] == [
        (0xFFF, "other"),
        (0x000, "nmt"),
        (0xF05, "other"),
    ]
