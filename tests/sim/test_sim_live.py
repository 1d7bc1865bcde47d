"""The simulator on a python-can virtual bus, in real time, against the canopen package's
client: the simulated devices must answer like real CiA 301 servers."""

from __future__ import annotations

import threading
import time

import can
import canopen
import pytest

from cananalyze.devices.builtin import load_builtin
from cananalyze.sim.session import build


@pytest.fixture
def live():
    profiles = {3: load_builtin("mcb560"), 5: load_builtin("dat7014")}
    channel = f"sim-{time.monotonic_ns()}"
    sim, nodes, _ = build(profiles, duration=5.0, master=False)
    bus = can.Bus(interface="virtual", channel=channel)
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel)
    clients = {nid: network.add_node(nid, prof.source) for nid, prof in profiles.items()}
    thread = threading.Thread(target=sim.run_realtime, args=(bus, 10.0), daemon=True)
    thread.start()
    for client in clients.values():
        client.nmt.wait_for_bootup(2.0)
    yield clients, nodes
    sim.stop()
    thread.join(2.0)
    assert not thread.is_alive()
    network.disconnect()
    bus.shutdown()


def test_canopen_client_reads_writes_and_supervises(live):
    clients, nodes = live
    dat = clients[5]
    # expedited and segmented uploads of the simulated object dictionary
    assert dat.sdo[0x1018][1].raw == 0x3CD
    assert dat.sdo[0x1000].raw == 0x00040191
    assert dat.sdo.upload(0x1008, 0) == b"DAT 7014"
    assert clients[3].sdo[0x1008].raw == "CO4201"
    # block upload (canopen checks the CRC) and block download
    with dat.sdo.open(0x1008, 0, "rb", block_transfer=True) as fp:
        assert fp.read() == b"DAT 7014"
    with dat.sdo.open(0x1A01, 1, "wb", block_transfer=True, size=4) as fp:
        fp.write((0x64010310).to_bytes(4, "little"))
    assert dat.sdo[0x1A01][1].raw == 0x64010310
    assert nodes[5].od.get(0x1A01, 1) == 0x64010310
    # expedited download and the abort of a read-only object
    with pytest.raises(canopen.SdoAbortedError) as err:
        dat.sdo[0x1018][1].raw = 1
    assert err.value.code == 0x06010002
    with pytest.raises(canopen.SdoAbortedError) as err:
        dat.sdo.upload(0x2FFF, 0)
    assert err.value.code == 0x06020000
    # heartbeat per 0x1017, NMT state changes seen in it
    dat.sdo[0x1017].raw = 50
    dat.nmt.wait_for_heartbeat(1.0)
    assert dat.nmt.state == "PRE-OPERATIONAL"
    dat.nmt.state = "OPERATIONAL"
    time.sleep(0.12)
    dat.nmt.wait_for_heartbeat(1.0)
    assert dat.nmt.state == "OPERATIONAL"
    dat.nmt.state = "STOPPED"
    time.sleep(0.12)
    dat.nmt.wait_for_heartbeat(1.0)
    assert dat.nmt.state == "STOPPED"
    assert nodes[5].state == 0x04


def test_canopen_client_receives_tpdos(live):
    clients, _ = live
    mcb = clients[3]
    mcb.tpdo.read(from_od=False)  # mapping as the simulated node reports it by SDO
    assert mcb.tpdo[2].cob_id == 0x283
    names = [v.name for v in mcb.tpdo[2].map]
    assert len(names) == 4 and all("6401" in n or "nalog" in n for n in names)
    mcb.sdo[0x1801][5].raw = 100  # event timer 100 ms
    mcb.nmt.state = "OPERATIONAL"
    mcb.tpdo[2].wait_for_reception(1.0)
    values = [v.raw for v in mcb.tpdo[2].map]
    assert 1000 < values[0] < 4000  # analog 0 drifting around 2.5 V in mV
