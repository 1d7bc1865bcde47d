"""Boot stories and LSS sequences in the outputs (issue 40): the HTML report's Boot and LSS
sections (read back with lxml; a device name from an EDS stays text), the JSONL lines
(json), the MCAP event log (the `mcap` package's reader) and `load().events`, all from one
candump log: node 5 aborts a configuration write (CiA 302-2 J), node 6 answers a vendor-ID
that differs from its declared EDS (D), node 7 is started and reports operational; an LSS
master selects an identity, gives it node-ID 10, stores it, then asks for node-ID 128 (the
slave refuses). A log without boot-up or LSS frames gets none of it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT
from lxml import html as lxml_html
from mcap.reader import make_reader

import cananalyze

HOSTILE = "<img src=x onerror=alert(1)>"  # the EDS's file name: its profile's name
PRODUCT = "<script>alert(2)</script>"  # the EDS's product name

FRAMES = [
    (0.000, "705#00"),
    (0.010, "706#00"),
    (0.020, "707#00"),
    (0.100, "606#4000100000000000"),  # node 6: device type 0x00030191 (as its EDS)
    (0.101, "586#4300100091010300"),
    (0.110, "606#4018100100000000"),  # vendor-ID 0x99 (its EDS: 0x3CD)
    (0.111, "586#4318100199000000"),
    (0.200, "605#2F60600001000000"),  # node 5: a write it aborts (read only)
    (0.201, "585#8060600002000106"),
    (0.300, "000#0107"),  # start node 7
    (0.500, "7E5#4099000000000000"),  # LSS switch state selective 0x99/1/2/3
    (0.501, "7E5#4101000000000000"),
    (0.502, "7E5#4202000000000000"),
    (0.503, "7E5#4303000000000000"),
    (0.504, "7E4#4400000000000000"),
    (0.510, "7E5#110A000000000000"),  # configure node-ID 10: ok
    (0.511, "7E4#1100000000000000"),
    (0.520, "7E5#1700000000000000"),  # store: ok
    (0.521, "7E4#1700000000000000"),
    (0.530, "7E5#1180000000000000"),  # configure node-ID 128: out of range
    (0.531, "7E4#1101000000000000"),
    (0.540, "7E5#0400000000000000"),  # switch state global: waiting
] + [(0.35 + 0.5 * k, "707#05") for k in range(7)]


def _write_log(path: Path, frames) -> Path:
    path.write_text("".join(f"({1000 + t:.6f}) vcan0 {f}\n" for t, f in sorted(frames)))
    return path


def cli(*args: str) -> subprocess.CompletedProcess:
    r = subprocess.run(
        [sys.executable, "-m", "cananalyze", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert r.returncode in (0, 1), r.stderr
    return r


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("commissioning")
    eds_text = (ROOT / "decoders" / "dat7130.eds").read_text()
    eds_text = eds_text.replace("ProductName=DAT 7130", f"ProductName={PRODUCT}")
    try:
        eds = d / f"{HOSTILE}.eds"
        eds.write_text(eds_text)
    except OSError:  # a file system without '<' or '>' in names
        eds = d / "payload.eds"
        eds.write_text(eds_text)
    net = d / "net.toml"
    net.write_text(f"[nodes.6]\neds = {json.dumps(eds.name)}\n")
    return {"log": _write_log(d / "c.log", FRAMES), "net": net, "dir": d, "eds": eds}


@pytest.fixture(scope="module")
def page(files) -> tuple[str, object]:
    out = files["dir"] / "c.html"
    cli("report", str(files["log"]), "--network", str(files["net"]), "-o", str(out), "-q")
    text = out.read_text()
    return text, lxml_html.fromstring(text)


def _section(tree, sid: str):
    found = tree.xpath(f'//section[@id="{sid}"]')
    assert len(found) == 1, sid
    return found[0]


def _rows(table) -> list[list[str]]:
    return [[c.text_content() for c in tr.xpath("./td|./th")] for tr in table.xpath(".//tr")]


def test_report_tells_each_node_s_boot_step_by_step(page):
    _, tree = page
    boot = _section(tree, "boot")
    stories = {d.get("id"): d for d in boot.xpath('./div[@class="boot"]')}
    assert set(stories) == {"boot-node-5-1", "boot-node-6-1", "boot-node-7-1"}
    n6 = stories["boot-node-6-1"]
    steps = _rows(n6.xpath(".//table")[0])
    assert steps[0] == ["time", "step", "result", "detail"]
    assert [r[1:3] for r in steps[1:]] == [
        ["boot-up", "seen"],
        ["identity: device type", "0x00030191"],
        ["identity: vendor-ID", "0x00000099"],
    ]
    text6 = n6.text_content()
    assert "stopped at: identity" in text6
    assert "CiA 302-2 error status: D: vendor-ID (0x1018:01) differs" in text6
    assert "vendor-ID 0x99, expected 0x3CD" in text6
    text5 = stories["boot-node-5-1"].text_content()
    assert "stopped at: configuration" in text5
    assert "J: configuration download failed" in text5
    assert "aborted 0x06010002" in text5
    n7 = stories["boot-node-7-1"]
    assert [r[1] for r in _rows(n7.xpath(".//table")[0])[1:]] == [
        "boot-up",
        "NMT start",
        "error control",
        "operational",
    ]
    assert "Result: operational" in n7.text_content()
    assert [a.get("href") for a in tree.xpath("//nav/a")][:5] == [
        "#findings",
        "#buses",
        "#nodes",
        "#boot",
        "#lss",
    ]


def test_report_lists_the_lss_steps_and_who_got_which_node_id(page):
    _, tree = page
    lss = _section(tree, "lss")
    assigned, steps = (_rows(t) for t in lss.xpath(".//table"))
    assert assigned == [
        ["time", "vendor-ID", "product code", "revision", "serial", "node-ID", "stored"],
        ["+0.511 s", "0x00000099", "0x00000001", "0x00000002", "0x00000003", "10", "yes"],
    ]
    assert [r[1:3] + [r[4]] for r in steps[1:]] == [
        ["switch state selective", "selected", "-"],
        ["configure node-ID", "ok", "10"],
        ["store configuration", "ok", "-"],
        ["configure node-ID", "error 1: node-ID out of range", "128"],
        ["switch state global", "sent", "-"],
    ]


def test_a_device_name_from_an_eds_stays_text(page, files):
    text, tree = page
    name = files["eds"].stem
    heads = [h.text_content() for h in _section(tree, "boot").xpath(".//h3")]
    assert f"Node 6 ({name}): boot-up 1 at +0.010 s" in heads
    assert not tree.xpath("//img") and not tree.xpath("//*[@onerror]")
    assert HOSTILE not in text and PRODUCT not in text
    # every script is the page's own: the two packed blobs and the loader
    assert len(tree.xpath("//script")) == 3


def test_jsonl_has_a_line_per_boot_story_and_lss_step(files):
    r = cli("decode", str(files["log"]), "--network", str(files["net"]), "--format", "jsonl")
    lines = [json.loads(x) for x in r.stdout.splitlines()]
    boot = [x for x in lines if x["kind"] == "boot"]
    lss = [x for x in lines if x["kind"] == "lss"]
    assert [(b["node"], b["result"], b["status"], b["stopped_at"]) for b in boot] == [
        (5, "stopped", "J", "configuration"),
        (6, "stopped", "D", "identity"),
        (7, "operational", None, None),
    ]
    assert boot[1]["status_text"] == "vendor-ID (0x1018:01) differs from the expected one (0x1F85)"
    assert boot[1]["t_boot"] == pytest.approx(1000.01)
    assert [(x["step"], x["result"], x["node_id"]) for x in lss] == [
        ("switch state selective", "selected", None),
        ("configure node-ID", "ok", 10),
        ("store configuration", "ok", None),
        ("configure node-ID", "error 1: node-ID out of range", 128),
        ("switch state global", "sent", None),
    ]
    assert {(x["vendor_id"], x["product_code"], x["revision"], x["serial"]) for x in lss[:4]} == {
        (0x99, 1, 2, 3)
    }
    # an LSS step's line follows the frame that ended it
    frames = [x["t"] for x in lines if x["kind"] == "frame"]
    pos = lines.index(lss[1])
    assert lines[pos - 1]["kind"] in ("frame", "lss") and frames[-1] >= lss[1]["t"]
    # --node 7: its story only, no LSS step (they belong to no node)
    r = cli("decode", str(files["log"]), "--format", "jsonl", "--node", "7")
    kinds = [json.loads(x)["kind"] for x in r.stdout.splitlines()]
    assert kinds.count("boot") == 1 and "lss" not in kinds


def test_mcap_event_log_holds_them(files):
    out = files["dir"] / "c.mcap"
    cli("export", str(files["log"]), "--network", str(files["net"]), "--mcap", str(out))
    logs = []
    with out.open("rb") as f:
        for _, _, message in make_reader(f).iter_messages(topics=["/canopen/events"]):
            logs.append(json.loads(message.data))
    by_text = {m["message"]: m for m in logs}
    stop6 = [m for t, m in by_text.items() if t.startswith("node 6: boot-up 1: stopped")]
    assert len(stop6) == 1 and stop6[0]["level"] == 4  # foxglove.Log ERROR
    assert stop6[0]["timestamp"] == {"sec": 1000, "nsec": 10_000_000}
    assert by_text["node 7: boot-up 1: operational"]["level"] == 2
    lss = [m for t, m in by_text.items() if t.startswith("LSS ")]
    assigned = by_text[
        "LSS configure node-ID: ok, node-ID 10 (vendor 0x00000099, product 0x00000001, "
        "revision 0x00000002, serial 0x00000003)"
    ]
    assert assigned["timestamp"] == {"sec": 1000, "nsec": 511_000_000}
    refused = [m for m in lss if "out of range" in m["message"]]
    assert len(lss) == 5 and refused[0]["level"] == 4


def test_load_events_table_has_them(files):
    cap = cananalyze.load(str(files["log"]), network=str(files["net"]))
    ev = cap.events
    boot = ev[ev["kind"] == "boot"]
    assert boot["node"].tolist() == [5, 6, 7]
    assert (ev["kind"] == "lss").sum() == 5
    # the same stories as load().boot (one judgement: decode/boot)
    assert cap.boot["status"].tolist()[:2] == ["J", "D"]


def test_a_log_without_boot_up_or_lss_gets_none(tmp_path):
    frames = [(0.1 * k, "705#05") for k in range(30)]
    frames += [(0.1 * k + 0.01, f"185#{k:02X}00") for k in range(30)]
    log = _write_log(tmp_path / "plain.log", frames)
    r = cli("decode", str(log), "--format", "jsonl")
    assert {json.loads(x)["kind"] for x in r.stdout.splitlines()} == {"frame"}
    out = tmp_path / "plain.html"
    cli("report", str(log), "-o", str(out), "-q")
    tree = lxml_html.fromstring(out.read_text())
    assert not tree.xpath('//section[@id="boot"]') and not tree.xpath('//section[@id="lss"]')
    cap = cananalyze.load(str(log))
    assert not cap.events["kind"].isin(["boot", "lss"]).any()


def test_summary_counts_the_lss_steps_of_the_one_follower(files):
    out = cli("decode", str(files["log"]), "--summary").stdout.splitlines()
    assert [x for x in out if x.startswith("LSS")] == [
        "LSS: 5 steps (load().lss lists them)",
        "LSS: node-ID 10 given to vendor 0x00000099, product 0x00000001, revision 0x00000002, "
        "serial 0x00000003 (stored)",
    ]
    rec = json.loads(cli("decode", str(files["log"]), "--summary", "--format", "jsonl").stdout)
    assert rec["lss_assignments"] == [
        {
            "t": pytest.approx(1000.511),
            "vendor_id": 0x99,
            "product_code": 1,
            "revision": 2,
            "serial": 3,
            "node_id": 10,
            "stored": True,
        }
    ]


@pytest.mark.parametrize("which", ["made", "sample"])
def test_load_reads_the_run_s_stories_and_they_are_what_following_again_gives(files, which):
    from pandas.testing import assert_frame_equal

    log, net = (
        (files["log"], files["net"])
        if which == "made"
        else (ROOT / "samples" / "commissioning.log", ROOT / "samples" / "network.toml")
    )
    cap = cananalyze.load(str(log), network=str(net))
    assert cap.commissioning  # the run's producer, kept
    again = cananalyze.load(str(log), network=str(net))
    again.commissioning = []  # a Capture without it follows the log itself
    for table in ("boot", "lss", "lss_assignments"):
        assert_frame_equal(getattr(cap, table), getattr(again, table))
    assert len(cap.boot) == (3 if which == "made" else 4)


def _cut(files, size: int) -> tuple[list[str], list[tuple]]:
    """JSON lines (frames, each followed by the records at its row) and the boot and LSS
    events of the log decoded in batches of `size` frames (live sniffing feeds 1)."""
    from cananalyze.decode.events.build import EventState, batch_events
    from cananalyze.formats.source import read_all
    from cananalyze.outputs.jsonl.encode import dumps
    from cananalyze.outputs.jsonl.records import jsonl_records
    from cananalyze.outputs.jsonl.rows import frame_record
    from cananalyze.pipeline import Options, build_decoder

    decoder = build_decoder(Options(network=files["net"]))
    fb = read_all(files["log"])
    lines, events, state, off = [], [], EventState(), 0
    batches = [decoder.decode(fb.take(slice(a, a + size))) for a in range(0, len(fb), size)]
    for batch in [*batches, decoder.finish()]:
        by_row: dict[int, list[dict]] = {}
        for row, rec in jsonl_records(batch):
            by_row.setdefault(row, []).append(rec)
        for i in range(len(batch) + 1):
            if i < len(batch):
                lines.append(dumps(frame_record(batch, i)))
            lines.extend(dumps(r) for r in by_row.get(i, ()))
        evs, _ = batch_events(batch, off, state)
        events += [tuple(e) for e in evs if e.kind in ("boot", "lss")]
        off += len(batch)
    return lines, events


def test_where_the_batches_are_cut_changes_nothing(files):
    whole = _cut(files, 1 << 20)
    assert sum('"kind":"lss"' in x for x in whole[0]) == 5 and len(whole[1]) == 8
    # each LSS step right after the frame that ended it (its event names that row)
    at = [k for k, x in enumerate(whole[0]) if '"kind":"lss"' in x]
    assert [json.loads(whole[0][k - 1])["t"] for k in at] == pytest.approx(
        [1000.504, 1000.511, 1000.521, 1000.531, 1000.54]
    )
    for size in (1, 3, 8):
        assert _cut(files, size) == whole, size


def test_an_unanswered_command_of_an_earlier_batch_ends_in_this_one(tmp_path):
    frames = [
        (0.0, "7E5#4099000000000000"),
        (0.001, "7E5#4101000000000000"),
        (0.002, "7E5#4202000000000000"),
        (0.003, "7E5#4303000000000000"),  # no slave answers
        (0.5, "705#05"),
        (0.6, "7E5#0400000000000000"),  # the next command: the selective switch had none
    ]
    log = _write_log(tmp_path / "u.log", frames)
    files = {"log": log, "net": None}
    lines, events = _cut(files, 4)  # the command ends batch 1, its end is in batch 2
    assert _cut(files, 1 << 20) == (lines, events)
    first = events[0]
    assert first[1:5] == (
        "lss",
        None,
        3,
        "LSS switch state selective: no answer "
        "(vendor 0x00000099, product 0x00000001, revision 0x00000002, "
        "serial 0x00000003)",
    )


def test_report_with_node_filter_and_without_times(files, tmp_path):
    out = tmp_path / "n7.html"
    cli("report", str(files["log"]), "--node", "7", "-o", str(out), "-q")
    tree = lxml_html.fromstring(out.read_text())
    heads = [h.text_content() for h in _section(tree, "boot").xpath(".//h3")]
    assert heads == ["Node 7: boot-up 1 at +0.020 s"]
    assert not tree.xpath('//section[@id="lss"]')  # LSS steps belong to no node
    # candump's screen output (no times): the steps in order, no time told
    untimed = tmp_path / "untimed.log"
    text = []
    for _, f in sorted(FRAMES):
        cob, data = f.split("#")
        octets = [data[k : k + 2] for k in range(0, len(data), 2)]
        text.append(f"  vcan0  {cob}   [{len(octets)}]  {' '.join(octets)}\n")
    untimed.write_text("".join(text))
    out = tmp_path / "untimed.html"
    cli("report", str(untimed), "-o", str(out), "-q")
    tree = lxml_html.fromstring(out.read_text())
    boot = _section(tree, "boot")
    assert [h.text_content() for h in boot.xpath(".//h3")] == [
        "Node 5: boot-up 1",
        "Node 6 (cia401): boot-up 1",  # identified by its device type read
        "Node 7: boot-up 1",
    ]
    n5 = _rows(boot.xpath(".//table")[0])
    assert [r[:2] for r in n5[1:]] == [["-", "boot-up"], ["-", "configuration 0x6060:00"]]
    assert "J: configuration download failed" in boot.text_content()
    assigned = _rows(_section(tree, "lss").xpath(".//table")[0])
    assert assigned[1][0] == "-" and assigned[1][-2:] == ["10", "yes"]
