"""SdoTracker on constructed traffic: interleaving, channels, protocol faults, block corners."""

from __future__ import annotations

import random
import struct

from cananalyze.decode.sdo import SdoTracker
from cananalyze.decode.sdo.tracker import block_crc


def _seg_upload(node: int, index: int, value: bytes) -> list[tuple[int, bytes]]:
    req, resp = 0x600 + node, 0x580 + node
    frames = [
        (req, struct.pack("<BHBI", 0x40, index, 1, 0)),
        (resp, struct.pack("<BHBI", 0x41, index, 1, len(value))),
    ]
    toggle = 0
    for off in range(0, len(value), 7):
        chunk = value[off : off + 7]
        last = off + 7 >= len(value)
        frames.append((req, bytes([0x60 | toggle << 4]) + bytes(7)))
        frames.append(
            (resp, (bytes([toggle << 4 | (7 - len(chunk)) << 1 | last]) + chunk).ljust(8, b"\0"))
        )
        toggle ^= 1
    return frames


def _feed(tracker: SdoTracker, frames, t0: float = 0.0):
    roles = [tracker.feed(t0 + i * 0.001, cob, data, i) for i, (cob, data) in enumerate(frames)]
    tracker.finish()
    return roles, tracker.pop_completed()


def test_interleaved_transfers_across_nodes_pair_correctly() -> None:
    rng = random.Random(7)
    streams = {
        node: _seg_upload(
            node, 0x2000 + node, bytes(rng.randrange(256) for _ in range(5 + 9 * node))
        )
        for node in range(1, 9)
    }
    values = {
        node: b"".join(
            d[1 : 8 - (d[0] >> 1 & 7)] for c, d in f if c == 0x580 + node and d[0] >> 5 == 0
        )
        for node, f in streams.items()
    }
    merged = []
    cursors = {node: 0 for node in streams}
    while cursors:
        node = rng.choice(sorted(cursors))
        merged.append(streams[node][cursors[node]])
        cursors[node] += 1
        if cursors[node] == len(streams[node]):
            del cursors[node]
    roles, txs = _feed(SdoTracker(), merged)
    assert all(r.problem is None for r in roles)
    assert sorted(tx.node for tx in txs) == list(range(1, 9))
    for tx in txs:
        assert tx.result == "ok" and tx.index == 0x2000 + tx.node
        assert bytes.fromhex(tx.data) == values[tx.node] and tx.frames == len(streams[tx.node])


def test_toggle_error_then_server_abort() -> None:
    frames = _seg_upload(3, 0x2003, b"0123456789ABCDEF")
    frames[4] = (0x603, bytes([0x60]) + bytes(7))  # second segment request repeats toggle 0
    frames = frames[:5] + [(0x583, struct.pack("<BHBI", 0x80, 0x2003, 1, 0x05030000))]
    roles, (tx,) = _feed(SdoTracker(), frames)
    assert roles[4].problem == "toggle bit not alternated (expected 1)"
    assert tx.result == "abort" and tx.abort_code == 0x05030000
    assert tx.detail.startswith("toggle bit not alternated")


def test_echo_mismatch_and_size_mismatch() -> None:
    frames = [
        (0x601, bytes.fromhex("4000200100000000")),
        (0x581, bytes.fromhex("4300200200000000")),
    ]
    roles, (tx,) = _feed(SdoTracker(), frames)
    assert tx.result == "protocol_error" and "response names 0x2000:02" in tx.detail
    frames = _seg_upload(1, 0x2001, b"abcdefghij")
    frames[1] = (0x581, struct.pack("<BHBI", 0x41, 0x2001, 1, 11))
    _, (tx,) = _feed(SdoTracker(), frames)
    assert tx.result == "protocol_error" and tx.detail == "size announced 11, assembled 10"


def _block_download(data: bytes, blksize: int, crc: int | None = None, drop: int | None = None):
    """Client block download to node 2 with sub-block size `blksize`; `drop` loses one segment once."""
    req, resp = 0x602, 0x582
    frames = [
        (req, struct.pack("<BHBI", 0xC6, 0x2100, 0, len(data))),
        (resp, struct.pack("<BHBB", 0xA4, 0x2100, 0, blksize) + bytes(3)),
    ]
    segments = [data[i : i + 7] for i in range(0, len(data), 7)]
    pos = 0
    while pos < len(segments):
        block = segments[pos : pos + blksize]
        acked = len(block)
        for seq, seg in enumerate(block, start=1):
            last = pos + seq == len(segments)
            if drop == pos + seq:
                drop, acked = None, seq - 1
                continue
            frames.append((req, (bytes([seq | last << 7]) + seg).ljust(8, b"\0")))
        frames.append((resp, bytes([0xA2, acked, blksize]) + bytes(5)))
        pos += acked
    n = (7 - len(data) % 7) % 7
    frames.append(
        (req, struct.pack("<BH", 0xC1 | n << 2, block_crc(data) if crc is None else crc) + bytes(5))
    )
    frames.append((resp, bytes([0xA1]) + bytes(7)))
    return frames


def test_block_download_retransmission_after_lost_segment() -> None:
    data = bytes(range(60))
    roles, (tx,) = _feed(SdoTracker(), _block_download(data, blksize=4, drop=6))
    assert tx.result == "ok" and bytes.fromhex(tx.data) == data
    assert any(r.problem and "seqno gap" in r.problem for r in roles)
    assert "to be repeated" in tx.detail


def test_block_download_crc_mismatch() -> None:
    frames = _block_download(bytes(range(20)), blksize=127, crc=0x1234)
    frames[-1] = (0x582, struct.pack("<BHBI", 0x80, 0x2100, 0, 0x05040004))
    roles, (tx,) = _feed(SdoTracker(), frames)
    assert "CRC mismatch: frame says 0x1234" in roles[-2].problem
    assert tx.result == "abort" and tx.abort_code == 0x05040004 and "CRC mismatch" in tx.detail


def test_block_upload_protocol_switch_to_segmented() -> None:
    frames = [(0x604, bytes.fromhex("A408100000 7F 0A 00".replace(" ", "")) + b"\0")]
    frames += _seg_upload(4, 0x1008, b"CPS_DCON\0")[1:]
    frames[1] = (0x584, struct.pack("<BHBI", 0x41, 0x1008, 0, 9))
    roles, (tx,) = _feed(SdoTracker(), frames)
    assert tx.index == 0x1008 and tx.subindex == 0
    assert (tx.protocol, tx.result) == ("segmented", "ok") and bytes.fromhex(
        tx.data
    ) == b"CPS_DCON\0"
    assert tx.detail == "server switched from block to normal upload"


def test_sdo_channel_learnt_from_server_parameter_write() -> None:
    tracker = SdoTracker()
    assert tracker.channel_of(0x6E0) is None
    frames = [
        (0x605, struct.pack("<BHBI", 0x23, 0x1201, 1, 0x6E0)),
        (0x585, struct.pack("<BHBI", 0x60, 0x1201, 1, 0)),
        (0x605, struct.pack("<BHBI", 0x23, 0x1201, 2, 0x6E1)),
        (0x585, struct.pack("<BHBI", 0x60, 0x1201, 2, 0)),
        (0x6E0, bytes.fromhex("4000100000000000")),
        (0x6E1, bytes.fromhex("4300100091010000")),
    ]
    _, txs = _feed(tracker, frames)
    assert tracker.channel_of(0x6E0) == (5, True) and tracker.channel_of(0x6E1) == (5, False)
    assert txs[-1].channel == (0x6E0, 0x6E1) and txs[-1].data == "91010000" and txs[-1].node == 5
