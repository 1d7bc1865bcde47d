"""USDO (CiA 1301, CANopen FD) transfers in the SDO table: expedited, segmented, bulk, aborts.

Two sources of frames, neither protocol/usdo.py's encoder:
  * tests/data/usdo_emsa.log: every frame built by Embedded Systems Academy's USDO
    codec (github.com/em-sa/SOFA-CANopenFD, `fbsec_co_fd_usdo.c` V3.1, which cites
    CiA 1301 v1.1 Tables 22, 31 and 32), by tests/data/usdo_emsa_frames.c;
  * frames written byte by byte below, from the layouts that codec documents
    (destination, command specifier, session ID, sub-index, index in bytes 4-5,
    data type, size, data from byte 8; a segment's counter in byte 3 and its data
    from byte 4; the last segment's byte count in byte 3; the abort's one-byte
    code in byte 6) and emtas' `ico_usdo.h` command specifiers (bulk 0x06/0x07/
    0x08 and 0x26/0x28, whose layouts are the module's `assumed` ones).
"""

from __future__ import annotations

import json

from conftest import ROOT

from cananalyze.core.frames import FLAG_FD
from cananalyze.protocol import usdo
from tests.decode.usdo_frames import decode_log

CLIENT, SERVER = 0x10, 5
REQ, RESP = 0x600 + CLIENT, 0x580 + SERVER


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


# expedited download: 0x2000:01 := 1000 (UNSIGNED32 = data type 0x07), session 1
EXP_DL = [
    (REQ, h("05 01 01 01 0020 07 04 e8030000")),  # 12 bytes: an FD length
    (RESP, h("10 21 01 01 0020")),  # 6 bytes
]
# expedited upload: 0x1017:00 = 500 (UNSIGNED16 = 0x06), session 2
EXP_UL = [
    (REQ, h("05 11 02 00 1710")),
    (RESP, h("10 31 02 00 1710 06 02 f401 0000")),  # 10 bytes, padded to 12
]
# upload of 0x2001:00 aborted by the server: 0x33 (object does not exist), session 3
ABORTED = [
    (REQ, h("05 11 03 00 0120")),
    (RESP, h("10 7f 03 00 0120 33")),
]


def test_the_table_holds_every_command_specifier_of_the_reference():
    ref = {0x01, 0x21, 0x11, 0x31, 0x02, 0x03, 0x04, 0x22, 0x23, 0x24, 0x32, 0x33, 0x34,
           0x13, 0x06, 0x07, 0x08, 0x26, 0x28, 0x7F}  # fmt: skip
    assert set(usdo.COMMANDS) == ref
    assert usdo.command_of(0x81).name == "download expedited request"  # remote variant
    assert usdo.abort_text(0x70) == "USDO server busy"


def test_the_encoder_writes_the_reference_bytes():
    frame = usdo.encode(0x01, SERVER, 1, index=0x2000, subindex=1, datatype=7,
                        data=(1000).to_bytes(4, "little"))  # fmt: skip
    assert frame == EXP_DL[0][1]
    assert usdo.encode(0x21, CLIENT, 1, index=0x2000, subindex=1) == EXP_DL[1][1]


def _decode_file(path):
    import subprocess
    import sys

    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(path), "--format", "jsonl"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    return [json.loads(x) for x in run.stdout.splitlines()]


def test_frames_from_the_emsa_codec_are_the_transfers_it_encoded():
    """tests/data/usdo_emsa.log: what tests/data/usdo_emsa_frames.c asked EmSA's codec
    to encode, transfer by transfer (client 1; servers 5 and 6)."""
    rows = _decode_file(ROOT / "tests" / "data" / "usdo_emsa.log")
    frames = [r for r in rows if r["kind"] == "frame"]
    assert len(frames) == 28 and {f["service"] for f in frames} == {"usdo_request", "usdo_response"}
    assert not [f for f in frames if "usdo_problem" in f or f["command"] == "invalid"]
    body = bytes(range(256))
    got = [(r["node"], r["direction"], r["protocol"], r["index"], r["subindex"], r["session"],
            r["result"], r["data"], r["abort_code"]) for r in rows if r["kind"] == "sdo"]  # fmt: skip
    assert got == [
        (5, "download", "usdo_expedited", 0x2010, 0, 1, "ok", "deadbeef", None),
        (5, "upload", "usdo_expedited", 0x1008, 0, 2, "ok", b"SOFA-FD".hex(), None),
        (5, "download", "usdo_segmented", 0x2020, 1, 3, "ok", body[:150].hex(), None),
        (5, "upload", "usdo_segmented", 0x2030, 2, 4, "ok", body[:130].hex(), None),
        (6, "upload", "usdo_segmented", 0x2040, 0, 6, "ok", body[:120].hex(), None),
        (6, "upload", "usdo", 0x6000, 1, 5, "abort", None, 0x33),
    ]
    assert {r["client"] for r in rows if r["kind"] == "sdo"} == {1}
    # each initiate and expedited frame names its object; segments name none
    named = {(f["usdo_cs"], f.get("index"), f.get("subindex")) for f in frames}
    assert (0x02, 0x2020, 1) in named and (0x32, 0x2030, 2) in named and (0x7F, 0x6000, 1) in named
    assert {(c, i) for c, i, _ in named if c in (0x03, 0x13, 0x23, 0x24, 0x33, 0x34)} == {
        (c, None) for c in (0x03, 0x13, 0x23, 0x24, 0x33, 0x34)}  # fmt: skip


def test_the_encoder_writes_what_the_emsa_codec_writes():
    """protocol/usdo.py's encoder (the simulator's) against the EmSA-encoded frames."""
    lines = (ROOT / "tests" / "data" / "usdo_emsa.log").read_text().splitlines()
    for line in lines:
        cob, data = line.split()[2].split("##")
        frame = bytes.fromhex(data[1:])
        f = usdo.parse(frame)
        fields = {k: v for k, v in f.items()
                  if k not in ("cmd", "remote", "destination", "command", "session", "size")}  # fmt: skip
        assert usdo.encode(f["command"], f["destination"], f["session"], **fields) == frame, line


def test_expedited_download_and_upload_are_sdo_table_rows():
    out = decode_log(EXP_DL + EXP_UL)
    rows = out.sdo
    assert [r["protocol"] for r in rows] == ["usdo_expedited", "usdo_expedited"]
    w, r = rows
    assert (w["node"], w["direction"], w["index"], w["subindex"]) == (5, "download", 0x2000, 1)
    assert (w["value"], w["size"], w["data"], w["result"]) == (1000, 4, "e8030000", "ok")
    assert (w["client"], w["session"], w["cob_ids"]) == (CLIENT, 1, [REQ, RESP])
    assert (r["direction"], r["value"], r["name"], r["words"]) == (
        "upload", 500, "Producer heartbeat time", "500 ms")  # fmt: skip
    assert r["latency_ms"] == 1.0


def test_frames_are_usdo_services_with_their_fields():
    out = decode_log(EXP_DL)
    req, resp = out.frames
    assert (req["service"], resp["service"]) == ("usdo_request", "usdo_response")
    assert req["fd"] is True and req["dlc"] == 12
    assert req["usdo_cs"] == 1 and req["command"] == "download_expedited_request"
    assert (req["destination"], req["session"], req["datatype"], req["size"]) == (5, 1, 7, 4)
    assert req["usdo_data"] == "e8030000"
    assert resp["destination"] == CLIENT and req["node"] == resp["node"] == SERVER


def test_an_abort_has_its_text():
    out = decode_log(ABORTED)
    (rec,) = out.sdo
    assert (rec["result"], rec["abort_code"]) == ("abort", 0x33)
    assert rec["abort_text"] == "Object does not exist in the object dictionary"
    assert "abort: 0x33 Object does not exist in the object dictionary" in out.text
    assert "node 5 USDO read 0x2001:00" in out.text


def test_segmented_upload_reassembles():
    blob = bytes(range(100))
    frames = [
        (REQ, h("05 11 04 00 0810")),
        (RESP, h("10 32 04 00 0810 09 00") + (100).to_bytes(4, "little")),  # total 100
        (REQ, h("05 13 04 00")),
        (RESP, h("10 33 04 00") + blob[:60]),  # 64 bytes
        (REQ, h("05 13 04 01")),
        (RESP, h("10 34 04 28") + blob[60:] + bytes(4)),  # 40 bytes: 44, padded to 48
    ]
    (rec,) = decode_log(frames).sdo
    assert (rec["protocol"], rec["result"], rec["size"]) == ("usdo_segmented", "ok", 100)
    assert rec["data"] == blob.hex() and rec["frames"] == 6


def test_segmented_download_and_bulk_download():
    blob = bytes(range(200, 256)) + bytes(range(30))
    seg = [
        (REQ, h("05 02 05 02 0020 0a 00") + len(blob).to_bytes(4, "little")),
        (RESP, h("10 22 05 02 0020")),
        (REQ, h("05 03 05 00") + blob[:60]),
        (RESP, h("10 23 05 00")),
        (REQ, h("05 04 05 1a") + blob[60:] + bytes(2)),  # 26 bytes: 30, padded to 32
        (RESP, h("10 24 05")),
    ]
    bulk = [
        (REQ, h("05 06 06 03 0020 0a 00") + len(blob).to_bytes(4, "little")),
        (RESP, h("10 26 06 03 0020")),
        (REQ, h("05 07 06 00") + blob[:60]),  # no answer per segment
        (REQ, h("05 08 06 1a") + blob[60:] + bytes(2)),
        (RESP, h("10 28 06")),
    ]
    a, b = decode_log(seg + bulk).sdo
    assert (a["protocol"], a["result"], a["data"]) == ("usdo_segmented", "ok", blob.hex())
    assert (b["protocol"], b["result"], b["data"]) == ("usdo_bulk", "ok", blob.hex())
    assert (a["session"], b["session"], b["frames"]) == (5, 6, 5)


def test_a_short_transfer_is_a_protocol_error_and_a_silent_one_a_timeout():
    short = [
        (REQ, h("05 02 07 02 0020 0a 00") + (100).to_bytes(4, "little")),
        (RESP, h("10 22 07 02 0020")),
        (REQ, h("05 04 07 04 01020304")),
        (RESP, h("10 24 07")),
    ]
    silent = [(REQ, h("05 11 08 00 0010"))]
    a, b = decode_log(short + silent).sdo
    assert a["result"] == "protocol_error" and "size announced 100, assembled 4" in a["detail"]
    assert b["result"] == "timeout"


def test_broadcast_each_server_answers_for_itself():
    frames = [
        (REQ, h("00 11 09 01 1810")),  # to every server: 0x1018:01
        (0x585, h("10 31 09 01 1810 07 04 78563412")),
        (0x586, h("10 31 09 01 1810 07 04 21436587")),
    ]
    recs = decode_log(frames).sdo
    assert [(r["node"], r["value"]) for r in recs] == [(5, 0x12345678), (6, 0x87654321)]
    assert all("broadcast request" in r["detail"] for r in recs)


def test_jsonl_records_carry_client_and_session():
    out = decode_log(EXP_DL)
    line = next(x for x in out.jsonl.splitlines() if '"kind":"sdo"' in x)
    rec = json.loads(line)
    assert rec["protocol"] == "usdo_expedited" and rec["client"] == CLIENT and rec["session"] == 1


def test_classic_sdo_stays_sdo_next_to_usdo():
    classic = [(0x605, h("4017100000000000")), (0x585, h("4b171000e8030000"))]
    out = decode_log(classic + EXP_DL, fd_rows={2, 3})
    assert [r["protocol"] for r in out.sdo] == ["expedited", "usdo_expedited"]
    assert [f["service"] for f in out.frames] == ["sdo_request", "sdo_response",
                                                  "usdo_request", "usdo_response"]  # fmt: skip


def test_nodes_marked_canopen_fd_read_unflagged_frames_as_usdo():
    # a log whose format lost the FD flag: the frames the marked nodes send (a USDO COB-ID
    # names its sender: client 0x10's requests, server 5's answers) are USDO
    # (8-byte frames: a classic frame holds no more)
    net = "[nodes.5]\ncanopen_fd = true\n[nodes.16]\ncanopen_fd = true\n"
    out = decode_log(ABORTED, fd_rows=set(), network=net)
    assert [(r["protocol"], r["abort_code"]) for r in out.sdo] == [("usdo", 0x33)]
    out = decode_log(ABORTED, fd_rows=set(), network="canopen_fd = true\n")
    assert [(r["protocol"], r["abort_code"]) for r in out.sdo] == [("usdo", 0x33)]
    out = decode_log(ABORTED, fd_rows=set(), fd=True)  # --fd: the whole network
    assert [(r["protocol"], r["abort_code"]) for r in out.sdo] == [("usdo", 0x33)]
    out = decode_log(ABORTED, fd_rows=set())  # unmarked: classic SDO (and nonsense)
    assert [r["protocol"] for r in out.sdo] != [("usdo")]
    assert [f.get("fd") for f in out.frames] == [None, None]  # no FD flag (FLAG_FD) logged
    assert FLAG_FD


def test_a_canopen_fd_network_has_64_byte_pdos_and_fd_emcy(tmp_path):
    import subprocess
    import sys

    net = tmp_path / "fd.toml"
    words = ", ".join(f'"0x2000{k:02X}40"' for k in range(1, 9))  # 8 x 64 bits = 512
    net.write_text(f"canopen_fd = true\n[nodes.5.tpdo.1]\nmapping = [{words}]\n")
    log = tmp_path / "pdo.log"
    log.write_text(
        "(1.000000) can0 705#05\n"
        "(1.010000) can0 085##01023000000000000000000\n"  # EMCY in an 11-byte FD frame
        f"(1.020000) can0 185##0{bytes(range(64)).hex()}\n"
    )
    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--network", str(net),
         "--format", "jsonl", "--signals"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    values = [json.loads(x)["value"] for x in run.stdout.splitlines()]
    assert values == [int.from_bytes(bytes(range(8 * k, 8 * k + 8)), "little") for k in range(8)]
    text = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--network", str(net)],
        capture_output=True, text=True, check=True,
    ).stdout  # fmt: skip
    assert "EMCY 0x2310" in text and "shorter" not in text


def test_the_network_file_keeps_64_bit_pdos_on_a_classic_node(tmp_path):
    import subprocess
    import sys

    net = tmp_path / "cc.toml"
    words = ", ".join(f'"0x2000{k:02X}40"' for k in range(1, 3))
    net.write_text(f"[nodes.5.tpdo.1]\nmapping = [{words}]\n")
    log = tmp_path / "x.log"
    log.write_text("(1.000000) can0 705#05\n")
    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--network", str(net)],
        capture_output=True, text=True,
    )  # fmt: skip
    assert run.returncode != 0 and "512 on a CANopen FD node" in run.stderr


def test_canopen_fd_in_the_network_file_is_true_or_false(tmp_path):
    import subprocess
    import sys

    net = tmp_path / "bad.toml"
    net.write_text('[nodes.5]\ncanopen_fd = "yes"\n')
    log = tmp_path / "x.log"
    log.write_text("(1.000000) can0 705#05\n")
    run = subprocess.run(
        [sys.executable, "-m", "cananalyze", "decode", str(log), "--network", str(net)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2 and "nodes.5.canopen_fd: expected true or false" in run.stderr
