"""SocketCAN error frames named by class as `candump -e` does (can-utils lib.c), in the
text and JSONL of a candump log; the same frames in a pcap are in test_readers_pcap."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from cananalyze.protocol import error_frame

# (identifier, data) -> what candump -e prints after ERRORFRAME (its "\n\t" as ", ")
CASES = [
    ("20000004", "0004000000000000", "controller-problem{rx-error-warning}"),
    ("20000020", "0000000000000000", "no-acknowledgement-on-tx"),
    ("20000040", "0000000000000000", "bus-off"),
    (
        "2000008A",
        "0500190300000000",
        "lost-arbitration{at bit 5}, protocol-violation{{single-bit-error,"
        "tx-dominant-bit-error,tx-recessive-bit-error}{start-of-frame}}, bus-error",
    ),
    ("20000200", "0000000000000A0F", "error-counter-tx-rx{{10}{15}}"),
    ("20000100", "0000000000000000", "restarted-after-bus-off"),
]


@pytest.mark.parametrize("ident, data, text", CASES)
def test_classes_as_candump(ident, data, text):
    f = error_frame.fields(int(ident, 16), bytes.fromhex(data))
    assert error_frame.text(f) == f"CAN error frame: {text}"


def test_candump_log_error_frames_in_text_and_jsonl(tmp_path):
    log = tmp_path / "err.log"
    log.write_text("".join(f"({k}.0) can0 {i}#{d}\n" for k, (i, d, _) in enumerate(CASES)))
    run = [sys.executable, "-m", "cananalyze", "decode", str(log)]
    text = subprocess.run(run, capture_output=True, text=True, check=True).stdout.splitlines()
    for line, (_, _, want) in zip(text, CASES, strict=True):
        assert line.endswith(f"CAN error frame: {want}"), line
    out = subprocess.run([*run, "--format", "jsonl"], capture_output=True, text=True, check=True)
    recs = [json.loads(x) for x in out.stdout.splitlines()]
    assert recs[0]["error_classes"] == ["controller-problem"]
    assert recs[0]["controller"] == ["rx-error-warning"]
    assert recs[3]["protocol"] == {
        "types": ["single-bit-error", "tx-dominant-bit-error", "tx-recessive-bit-error"],
        "location": "start-of-frame",
    }
    assert recs[3]["lost_arbitration_bit"] == 5
    assert (recs[4]["tx_errors"], recs[4]["rx_errors"]) == (10, 15)


def test_error_frames_without_socketcan_layout_name_no_class():
    """An ASC or BLF error frame (no 8-byte SocketCAN layout) is not read for classes."""
    assert error_frame.fields(0x181, b"") == {}
    assert error_frame.text({}) == "CAN error frame"
