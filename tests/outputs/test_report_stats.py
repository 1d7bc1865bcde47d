"""Issue 44 item 1: the report's statistics are the ones `decode --summary` prints and
the ones numpy computes over the exported Parquet, on a real log (PEAK TRC, pcan3):
heartbeat periods, PDO gaps and SDO latencies from one computation, not from binned
plots (the report used to say median = p99 = max = 1400.93 ms where numpy gives
1400.05 and 1400.75)."""

from __future__ import annotations

import html
import re
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import real_file

PCAN3 = "hilch__canopen-message-interpreter/pcan3.trc"
NUM = r"([\d.]+)"


def _cli(*args: str) -> str:
    done = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args], capture_output=True, text=True, check=False
    )
    assert done.returncode in (0, 1), done.stderr
    return done.stdout


@pytest.fixture(scope="module")
def pcan3(tmp_path_factory):
    log = real_file(PCAN3)
    tmp = tmp_path_factory.mktemp("pcan3")
    _cli("report", str(log), "-o", str(tmp / "r.html"))
    page = html.unescape(re.sub(r"<[^>]+>", " ", (tmp / "r.html").read_text()))
    page = re.sub(r"\s+", " ", page)
    summary = _cli("decode", str(log), "--summary")
    _cli("export", str(log), "--parquet", str(tmp / "pq"), "-q")
    frames = pq.read_table(tmp / "pq" / "frames.parquet").to_pandas()
    return page, summary, frames


def _summary_block(summary: str, title: str) -> dict[str, list[str]]:
    """`key: n=.. min .. median .. mean .. p99 .. max ..` lines under a summary title."""
    lines = summary.split(title, 1)[1].splitlines()[1:]
    out = {}
    for line in lines:
        if not line.startswith("  "):
            break
        m = re.match(
            rf"\s+(\S+(?: +\d+)?): (?:rate \S+ Hz )?n={NUM} min {NUM} median {NUM} "
            rf"mean {NUM} p99 {NUM} max {NUM}",
            line,
        )
        if m:
            out[m.group(1).replace(" ", "")] = list(m.groups()[1:])
    return out


def test_heartbeat_periods_as_summary_and_numpy(pcan3):
    page, summary, frames = pcan3
    want = _summary_block(summary, "heartbeat period per node:")
    assert len(want) >= 3
    got = {
        f"node{m.group(1)}": list(m.groups()[1:])
        for m in re.finditer(
            rf"Node (\d+): (?:(?!Node \d+:).)*?heartbeat period: n={NUM} min {NUM} median {NUM} mean {NUM} "
            rf"p99 {NUM} max {NUM}",
            page,
        )
    }
    for node, numbers in want.items():
        assert got[node] == numbers, node
    # numpy over the Parquet frames, read by pyarrow: the same median and p99
    for node in (1, 15, 40):
        hb = frames[(frames.service == "heartbeat") & (frames.node == node)]
        gaps = np.diff(hb.t.to_numpy()) * 1000.0
        n, _, median, _, p99, _ = want[f"node{node}"]
        assert int(n) == gaps.size
        assert float(median) == pytest.approx(np.median(gaps), abs=0.005)
        assert float(p99) == pytest.approx(np.percentile(gaps, 99), abs=0.005)


def test_pdo_gaps_and_sdo_latencies_as_summary(pcan3):
    page, summary, frames = pcan3
    pdo = _summary_block(summary, "PDO gaps per COB-ID:")
    assert "0x18F" in pdo
    for cob, (_, lo, median, _, _, hi) in pdo.items():
        row = re.search(rf"{cob} \d+ \S+ [\d,]+ \S+ {NUM} {NUM} {NUM}", page)
        assert row is not None, cob
        assert list(row.groups()) == [lo, median, hi], cob
    tp = frames[frames.can_id == 0x18F]
    assert float(pdo["0x18F"][2]) == pytest.approx(
        np.median(np.diff(tp.t.to_numpy())) * 1000, abs=0.005
    )
    sdo = _summary_block(summary, "SDO latency per node:")
    assert len(sdo) >= 3
    for node, (_, lo, median, _, p99, hi) in sdo.items():
        number = node.removeprefix("node")
        row = re.search(rf"\b{number} \d+ \d+ {NUM} {NUM} {NUM} {NUM}", page)
        assert row is not None, node
        assert list(row.groups()) == [lo, median, p99, hi], node
