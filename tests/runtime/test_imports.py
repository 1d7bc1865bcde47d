"""The program imports python-can without asammdf (runtime/imports.py), and nothing else changes.

python-can imports asammdf eagerly for its MF4Reader; the program hides it from that
import only. Checked in a process of its own, as the program runs: python-can and canopen
imported (a network file's EDS parsed, with the device files' cache off: a warm cache
imports neither), asammdf not; MF4 input still read, by cananalyze's own reader, in such a process; and a library
import (no `program`) leaves python-can's MF4Reader whole.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import can  # before asammdf: asammdf's own import imports python-can halfway through
import pytest
from conftest import ROOT, SAMPLES

pytest.importorskip("asammdf")

PROBE = """
import json, sys
sys.argv = ["cananalyze", *sys.argv[1:]]
from cananalyze.cli.main import program
try:
    rc = program()
except SystemExit as e:
    rc = e.code
import can.io.mf4
print(json.dumps({"rc": rc, "can": "can" in sys.modules, "canopen": "canopen" in sys.modules,
    "asammdf": "asammdf" in sys.modules, "mf4reader": can.io.mf4.asammdf is not None}),
    file=sys.stderr)
"""


ENV = {**os.environ, "CANANALYZE_CACHE": "off"}  # every EDS parsed by canopen
PARSES = ("decode", str(SAMPLES / "faults.log"), "--network", str(SAMPLES / "network.toml"))


def _probe(*args: str) -> tuple[dict, str]:
    done = subprocess.run(
        [sys.executable, "-c", PROBE, *args], capture_output=True, text=True, cwd=ROOT, env=ENV
    )
    return json.loads(done.stderr.strip().splitlines()[-1]), done.stdout


def test_a_decode_that_parses_an_eds_does_not_import_asammdf():
    got, out = _probe(*PARSES)
    assert got["rc"] in (0, 1) and out.count("\n") > 100
    assert got["can"] and got["canopen"]  # the network file's EDS files parsed
    assert not got["asammdf"] and not got["mf4reader"]
    same = subprocess.run(
        [sys.executable, "-c", "from cananalyze.cli.main import main; main()", *PARSES],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=ENV,
    )
    assert same.stdout == out  # the library's `main` (python-can whole) prints the same


def test_mf4_input_is_still_read_by_cananalyze_own_reader(tmp_path):
    log = tmp_path / "x.log"
    log.write_text("".join(f"({1.0 + i / 100:.6f}) can0 18{i % 8}#{i:02X}00\n" for i in range(40)))
    mf4 = tmp_path / "x.mf4"
    with can.MF4Writer(str(mf4)) as w:  # python-can's writer (this process has it whole)
        for msg in can.LogReader(str(log)):
            w.on_message_received(msg)
    got, out = _probe("decode", "--format", "jsonl", str(mf4))
    assert got["rc"] == 0 and got["asammdf"]  # imported by formats/logs/mf4.py itself
    frames = [json.loads(x) for x in out.splitlines() if '"kind":"frame"' in x]
    assert [f["data"] for f in frames] == [f"{i:02x}00" for i in range(40)]


def test_a_library_import_keeps_python_can_whole():
    code = "import cananalyze, canopen, can.io.mf4; print(can.io.mf4.asammdf is not None)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.stdout.strip() == "True", done.stderr
