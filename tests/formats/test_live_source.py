"""LiveSource on python-can's virtual bus: every frame arrives, in order, and decodes
exactly as the same frames do offline."""

from __future__ import annotations

import threading
import time

import can
import numpy as np
import pytest
from conftest import SAMPLES

from cananalyze.core.frames import FLAG_TX, concat
from cananalyze.formats.live import HwFilter, LiveError, LiveSource, open_bus
from cananalyze.formats.logs._pycan_writer import to_messages
from cananalyze.formats.source import read_all
from cananalyze.outputs.fields import row_fields
from cananalyze.pipeline import Decoder
from cananalyze.protocol.fields import annotation


def _pump(channel: str, messages, source: LiveSource, pause_every: int = 0) -> threading.Thread:
    def run():
        tx = can.Bus(interface="virtual", channel=channel)
        try:
            for k, msg in enumerate(messages):
                tx.send(msg)
                if pause_every and k % pause_every == 0:
                    time.sleep(0.001)
            time.sleep(0.3)
        finally:
            tx.shutdown()
            source.stop()

    th = threading.Thread(target=run)
    th.start()
    return th


def test_demo_frames_arrive_whole_and_decode_like_offline():
    offline = read_all(SAMPLES / "demo.log")
    rx = can.Bus(interface="virtual", channel="live-demo")
    source = LiveSource(rx, interval=0.01, batch_max=16)
    th = _pump("live-demo", list(to_messages(offline)), source, pause_every=10)
    got = [b for b in source.batches()]
    th.join()
    assert sum(1 for b in got if len(b)) > 1  # small batches, as live traffic comes
    live = concat([b for b in got if len(b)])
    assert len(live) == len(offline) == 185
    np.testing.assert_array_equal(live.can_id, offline.can_id)
    np.testing.assert_array_equal(live.dlc, offline.dlc)
    np.testing.assert_array_equal(live.data, offline.data)
    # the virtual bus stamps frames when sent; direction becomes "received"
    assert (np.diff(live.t) >= 0).all() and abs(live.t[-1] - time.time()) < 60
    np.testing.assert_array_equal(live.flags, offline.flags & ~np.uint8(FLAG_TX))
    np.testing.assert_array_equal(live.line, np.arange(1, 186))
    assert live.channels == ("live-demo",)

    # the same Decoder, fed the live batches one by one, says what it says offline
    dec_live, dec_off = Decoder(), Decoder()
    live_fields = []
    for b in got:
        d = dec_live.decode(b)
        live_fields += [
            annotation(int(d.service[i]), int(d.node[i]), int(d.pdo[i]), row_fields(d, i))
            for i in range(len(b))
        ]
    d = dec_off.decode(offline)
    off_fields = [
        annotation(int(d.service[i]), int(d.node[i]), int(d.pdo[i]), row_fields(d, i))
        for i in range(len(offline))
    ]
    assert live_fields == off_fields
    assert "EMCY 0x8100" in " ".join(live_fields)


def test_ring_full_waits_instead_of_dropping():
    rx = can.Bus(interface="virtual", channel="live-ring")
    source = LiveSource(rx, interval=0.05, batch_max=1 << 20, ring_size=64)
    n = 5000
    msgs = [
        can.Message(
            arbitration_id=0x180 + (k % 7), data=k.to_bytes(4, "little"), is_extended_id=False
        )
        for k in range(n)
    ]
    th = _pump("live-ring", msgs, source)
    batches = []
    for b in source.batches():
        batches.append(b)
        time.sleep(0.002)  # a slow consumer
    th.join()
    live = concat([b for b in batches if len(b)])
    assert len(live) == n
    values = live.data[:, :4].copy().view("<u4").ravel()
    np.testing.assert_array_equal(values, np.arange(n))
    assert (live.data[:, 4:] == 0).all()  # reused ring slots hold no stale bytes
    assert source.stalls > 0 and source.high_water <= 64


def test_long_and_remote_frames_keep_their_lengths():
    rx = can.Bus(interface="virtual", channel="live-fd", fd=True)
    source = LiveSource(rx, interval=0.01)
    msgs = [
        can.Message(
            arbitration_id=0x1ABCDE0, data=bytes(range(12)), is_fd=True, bitrate_switch=True
        ),
        can.Message(arbitration_id=0x705, is_remote_frame=True, dlc=1, is_extended_id=False),
        can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=False),
    ]
    th = _pump("live-fd", msgs, source)
    live = concat([b for b in source.batches() if len(b)])
    th.join()
    assert live.payload(0) == bytes(range(12)) and live.dlc[0] == 12
    assert live.dlc[1] == 1 and live.payload(1) == b"\x00"[:0] + bytes(live.data[1, :1])
    assert (live.data[1] == 0).all()
    assert live.payload(2) == b"\x01\x02"


def test_hardware_filter_reaches_the_interface():
    rx = open_bus("virtual", "live-filter", None, [HwFilter.parse("580:780")])
    source = LiveSource(rx, interval=0.01)
    msgs = [
        can.Message(arbitration_id=i, data=b"\x00", is_extended_id=False)
        for i in (0x585, 0x605, 0x183, 0x5FF, 0x581)
    ]
    th = _pump("live-filter", msgs, source)
    live = concat([b for b in source.batches() if len(b)])
    th.join()
    assert live.can_id.tolist() == [0x585, 0x5FF, 0x581]


@pytest.mark.parametrize("text", ["580", "xyz:7ff", "1:2:3", "40000000:0"])
def test_bad_filters_are_refused(text):
    with pytest.raises(ValueError, match="filter"):
        HwFilter.parse(text)


def test_unknown_interface_is_one_line():
    with pytest.raises(LiveError, match="nosuchbus"):
        open_bus("nosuchbus", "can0")
