"""The `consistency` rule on python-canopen traffic: canopen's SDO client configures two
canopen LocalNodes over python-can's virtual bus. Asserted on the configuration the
findings name, never on the bus's timing (the virtual bus runs on Python threads)."""

from __future__ import annotations

import time

import can
import canopen
from canopen.objectdictionary import UNSIGNED8, UNSIGNED16, UNSIGNED32, ODRecord

import cananalyze
from cananalyze.core.frames import from_rows
from cananalyze.formats.logfile import write_log
from tests.helpers.virtual_bus import drain, patient_client, unique_channel, variable


def _od(node: int) -> canopen.ObjectDictionary:
    """The communication objects the master writes: 0x1005, 0x1016:1, 0x1017, TPDO1."""
    od = canopen.ObjectDictionary()
    od.add_object(variable(0x1005, 0, "COB-ID SYNC", UNSIGNED32, "rw", 0x80))
    consumer = ODRecord("Consumer heartbeat time", 0x1016)
    consumer.add_member(variable(0x1016, 0, "Highest sub-index", UNSIGNED8, "ro", 1))
    consumer.add_member(variable(0x1016, 1, "Consumer 1", UNSIGNED32, "rw", 0))
    od.add_object(consumer)
    od.add_object(variable(0x1017, 0, "Producer heartbeat time", UNSIGNED16, "rw", 0))
    comm = ODRecord("TPDO1 communication parameter", 0x1800)
    comm.add_member(variable(0x1800, 0, "Highest sub-index", UNSIGNED8, "ro", 5))
    comm.add_member(variable(0x1800, 1, "COB-ID", UNSIGNED32, "rw", 0x180 + node))
    comm.add_member(variable(0x1800, 2, "Transmission type", UNSIGNED8, "rw", 255))
    od.add_object(comm)
    mapping = ODRecord("TPDO1 mapping parameter", 0x1A00)  # canopen's TPDO needs the pair
    mapping.add_member(variable(0x1A00, 0, "Number of mapped objects", UNSIGNED8, "rw", 1))
    mapping.add_member(variable(0x1A00, 1, "Mapped object 1", UNSIGNED32, "rw", 0x20000010))
    od.add_object(mapping)
    return od


def _traffic(writes: list[tuple[int, int, int, int, int]]):
    """Nodes 5 and 6 boot, node 5 sends its heartbeat; canopen's SDO client makes the
    writes (node, index, sub, value, size). The frames as (t, id, data, flags) rows."""
    channel = unique_channel("consistency")
    slaves, master = canopen.Network(), canopen.Network()
    slaves.connect(interface="virtual", channel=channel)
    master.connect(interface="virtual", channel=channel)
    recorder = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    locals_ = {n: canopen.LocalNode(n, _od(n)) for n in (5, 6)}
    try:
        remotes = {n: patient_client(n) for n in (5, 6)}
        for n in (5, 6):
            slaves.add_node(locals_[n])
            master.add_node(remotes[n])
            locals_[n].nmt.send_command(0x81)  # boot-up
        locals_[5].nmt.start_heartbeat(100)
        for node, index, sub, value, size in writes:
            remotes[node].sdo.download(index, sub, value.to_bytes(size, "little"))
        time.sleep(0.05)
        frames = drain(recorder)
    finally:
        locals_[5].nmt.stop_heartbeat()
        master.disconnect()
        slaves.disconnect()
        recorder.shutdown()
    return [(m.timestamp, m.arbitration_id, bytes(m.data), 0) for m in frames]


def _consistency(tmp_path, rows):
    log = tmp_path / "traffic.log"
    write_log(from_rows(sorted(rows, key=lambda r: r[0])), log)
    f = cananalyze.load(log).findings
    return f[f.rule == "consistency"].reset_index(drop=True)


def test_contradictions_canopen_configured_are_found_and_ended(tmp_path):
    rows = _traffic(
        [
            (5, 0x1017, 0, 100, 2),
            (6, 0x1016, 1, (5 << 16) | 100, 4),  # consumer time = producer time
            (6, 0x1016, 1, (5 << 16) | 300, 4),  # resolved
            (5, 0x1800, 1, 0x185, 4),
            (6, 0x1800, 1, 0x185, 4),  # node 6's TPDO1 on node 5's COB-ID
            (6, 0x1800, 1, 0x186, 4),  # resolved
            (5, 0x1005, 0, 0x40000080, 4),
            (6, 0x1005, 0, 0x40000080, 4),  # a second SYNC producer
        ]
    )
    f = _consistency(tmp_path, rows)
    assert list(f.severity) == ["warning", "error", "warning"]
    hb, cob, sync = f.to_dict("records")
    assert hb["node"] == 6 and hb["cob_id"] == 0x705 and hb["measured"] == 100
    assert "consumer time for node 5 is 100 ms" in hb["message"]
    assert hb["basis"].startswith("0x1016:1 written at") and "; 0x1017 written at" in hb["basis"]
    assert cob["cob_id"] == 0x185 and cob["node"] == 6
    assert "node 5's TPDO1, node 6's TPDO1" in cob["message"]
    assert cob["basis"].count("0x1800:1 written at") == 2
    assert "node 5's SYNC producer, node 6's SYNC producer" in sync["message"]
    assert sync["basis"].count("0x1005 written at") == 2


def test_a_consistent_canopen_configuration_gives_nothing(tmp_path):
    rows = _traffic(
        [
            (5, 0x1017, 0, 100, 2),
            (6, 0x1016, 1, (5 << 16) | 300, 4),
            (5, 0x1800, 1, 0x185, 4),
            (6, 0x1800, 1, 0x186, 4),
            (5, 0x1005, 0, 0x40000080, 4),  # one SYNC producer
            (6, 0x1005, 0, 0x80, 4),
        ]
    )
    assert len(_consistency(tmp_path, rows)) == 0
