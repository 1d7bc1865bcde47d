"""simulate --scenario fd: CANopen FD's USDO traffic, as samples/fd.* holds it, decoded back."""

from __future__ import annotations

import re

import pytest
from conftest import ROOT, SAMPLES

from cananalyze.core.frames import FLAG_FD
from cananalyze.decode.sdo.processor import SdoProcessor
from cananalyze.formats.source import read_all
from cananalyze.pipeline import Decoder
from cananalyze.protocol.services import Service


def _usdo(path):
    batch = read_all(path)
    dec = Decoder([SdoProcessor()])
    out, fin = dec.decode(batch), dec.finish()
    recs = [r for _, r in [*out.records, *fin.records] if r["kind"] == "sdo"]
    return batch, out, [r for r in recs if str(r["protocol"]).startswith("usdo")]


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_the_fd_sample_decodes_to_its_usdo_transfers(suffix):
    batch, out, recs = _usdo(SAMPLES / f"fd{suffix}")
    nodes = sorted({r["node"] for r in recs})
    assert nodes == [3, 5, 6, 7]
    per_node = {n: [(r["index"], r["protocol"], r["result"]) for r in recs if r["node"] == n]
                for n in nodes}  # fmt: skip
    assert per_node[5] == [
        (0x1018, "usdo_expedited", "ok"),
        (0x1017, "usdo_expedited", "ok"),
        (0x1008, "usdo_segmented", "ok"),
        (0x2F00, "usdo_bulk", "ok"),
    ]
    assert per_node[3][-1] == (0x5FFF, "usdo", "abort")  # the one abort: 0x33
    assert [r["abort_code"] for r in recs if r["result"] == "abort"] == [0x33]
    assert {r["client"] for r in recs} == {127}
    by_name = {r["node"]: r["value"] for r in recs if r["index"] == 0x1008}
    assert by_name[5] == "DAT 7014"  # read from the simulated node's dictionary
    usdo_rows = (out.service == Service.USDO_REQUEST) | (out.service == Service.USDO_RESPONSE)
    assert usdo_rows.sum() > 0 and ((batch.flags[usdo_rows] & FLAG_FD) != 0).all()


def test_the_docs_example_is_what_decode_prints():
    import subprocess
    import sys

    page = (ROOT / "docs" / "decoding.md").read_text()
    block = page.split("`tests/data/usdo.log`, a client (node 127)")[1].split("```")[1]
    shown = [line for line in block.strip("\n").splitlines() if "…" not in line]
    text = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(ROOT / "tests/data/usdo.log"),
         "--no-color"], capture_output=True, text=True, check=True,
    ).stdout.splitlines()  # fmt: skip
    assert shown and all(line in text for line in shown)
    assert len(re.findall("USDO (read|write)", block)) == 4
