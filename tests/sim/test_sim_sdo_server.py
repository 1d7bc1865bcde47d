"""The simulator's SDO server, frame by frame against CiA 301, and its CRC."""

from __future__ import annotations

import struct

from cananalyze.devices.builtin import load_builtin
from cananalyze.protocol.crc import crc16
from cananalyze.sim.dictionary import Dictionary
from cananalyze.sim.sdo_server import SdoServer


def server(key: str = "dat7014", node: int = 5) -> SdoServer:
    return SdoServer(Dictionary(load_builtin(key), node))


def h(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def test_crc16_is_ccitt_xmodem():
    assert crc16(b"123456789") == 0x31C3  # the CRC-16/XMODEM check value
    assert crc16(b"") == 0
    assert crc16(b"6789", crc16(b"12345")) == 0x31C3  # continues across blocks


def test_expedited_upload_matches_the_manual_demo():
    # the DAT 7014's vendor ID, as the bundled demo sample shows it
    assert server().handle(h("40 18 10 01 00000000")) == [h("43 18 10 01 cd030000")]


def test_segmented_upload_with_toggle():
    s = server()
    assert s.handle(h("40 08 10 00 00000000")) == [h("41 08 10 00 08000000")]
    assert s.handle(h("60 00000000000000")) == [h("00") + b"DAT 701"]
    assert s.handle(h("70 00000000000000")) == [h("1d") + b"4" + bytes(6)]  # n=6, c=1
    assert s.t is None


def test_toggle_error_aborts():
    s = server()
    s.handle(h("40 08 10 00 00000000"))
    assert s.handle(h("70 00000000000000")) == [h("80 08 10 00 00000305")]


def test_download_expedited_and_size_checks():
    s = server()
    assert s.handle(h("2b 17 10 00 6400 0000")) == [h("60 17 10 00 00000000")]
    assert s.od.get(0x1017, 0) == 100
    # 4 bytes into an UNSIGNED16: data type length too high
    assert s.handle(h("23 17 10 00 64000000")) == [h("80 17 10 00 12000706")]
    assert s.handle(h("23 18 10 01 01000000")) == [h("80 18 10 01 02000106")]  # read-only
    assert s.handle(h("40 ff 2f 00 00000000")) == [h("80 ff 2f 00 00000206")]  # no object
    assert s.handle(h("40 18 10 09 00000000")) == [h("80 18 10 09 11000906")]  # no sub-index


def test_segmented_download():
    s = server()
    assert s.handle(h("21 01 1a 01 04000000")) == [h("60 01 1a 01 00000000")]
    assert s.handle(h("07 10030164 000000")) == [h("20 00000000000000")]  # n=3, c=1
    assert s.od.get(0x1A01, 1) == 0x64010310


def test_block_upload_with_crc_and_retransmission():
    s = server("mcb560", 3)
    init = s.handle(h("a4 08 10 00 02 00 0000"))  # CRC, blksize 2, no protocol switch
    assert init == [h("c6 08 10 00 06000000")]
    # 6 bytes: one segment, last
    segs = s.handle(h("a3 00000000000000"))
    assert segs == [h("81") + b"CO4201\x00"]
    # the client missed it: ackseq 0 makes the server send it again
    assert s.handle(h("a2 00 02 0000000000")) == segs
    end = s.handle(h("a2 01 02 0000000000"))
    assert end == [bytes([0xC1 | 1 << 2]) + struct.pack("<H", crc16(b"CO4201")) + bytes(5)]
    assert s.handle(h("a1 00000000000000")) == []
    assert s.t is None


def test_block_upload_protocol_switch():
    # pst 8 >= 4 bytes: the server answers with an expedited upload (CiA 301 7.2.4.3.13)
    assert server().handle(h("a4 18 10 01 7f 08 0000")) == [h("43 18 10 01 cd030000")]


def test_block_download_checks_the_crc():
    s = server()
    value = (0x64010210).to_bytes(4, "little")
    assert s.handle(h("c6 01 1a 02 04000000")) == [h("a4 01 1a 02 7f 000000")]
    assert s.handle(bytes([0x81]) + value + bytes(3)) == [h("a2 01 7f 0000000000")]
    bad = s.handle(bytes([0xC1 | 3 << 2]) + struct.pack("<H", crc16(value) ^ 1) + bytes(5))
    assert bad == [h("80 01 1a 02 04000405")]
    s.handle(h("c6 01 1a 02 04000000"))
    s.handle(bytes([0x81]) + value + bytes(3))
    ok = s.handle(bytes([0xC1 | 3 << 2]) + struct.pack("<H", crc16(value)) + bytes(5))
    assert ok == [h("a1 00000000000000")]
    assert s.od.get(0x1A01, 2) == 0x64010210


def test_forced_abort_for_fault_injection():
    s = server()
    s.abort_codes[(0x1008, 0)] = 0x08000020
    assert s.handle(h("40 08 10 00 00000000")) == [h("80 08 10 00 20000008")]
