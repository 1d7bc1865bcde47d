"""The canopen package configures a PDO over SDO on a virtual bus; we decode what it set up."""

from __future__ import annotations

import time

import can
import canopen
import pytest

from cananalyze.config.spec import NetworkSpec, NodeSpec
from cananalyze.core.frames import from_rows
from cananalyze.decode.model import NetworkModel
from cananalyze.decode.pdo_processor import PdoDecoder
from cananalyze.decode.sdo.processor import SdoProcessor
from cananalyze.devices.profile import load_eds
from cananalyze.outputs.fields import row_fields
from cananalyze.pipeline import Decoder
from tests.conftest import real_file
from tests.helpers.virtual_bus import patient_client


def _record_configuration(eds: str, channel: str) -> list[tuple[float, int, bytes]]:
    rec = can.Bus(interface="virtual", channel=channel)
    master, slave = canopen.Network(), canopen.Network()
    master.connect(interface="virtual", channel=channel)
    slave.connect(interface="virtual", channel=channel)
    try:
        local = canopen.LocalNode(2, eds)
        slave.add_node(local)
        remote = patient_client(2, eds)
        master.add_node(remote)
        remote.tpdo.read()
        tpdo = remote.tpdo[1]
        tpdo.clear()
        tpdo.add_variable("INTEGER16 value")
        tpdo.add_variable("INTEGER32 value")
        tpdo.cob_id = 0x1A2
        tpdo.trans_type = 254
        tpdo.enabled = True
        tpdo.save()
        local.tpdo.read(from_od=False)  # the slave's PDO as the master's SDO writes left it
        local.tpdo[1]["INTEGER16 value"].raw = -1234
        local.tpdo[1]["INTEGER32 value"].raw = 70000
        local.tpdo[1].transmit()
        time.sleep(0.05)
        frames = []
        while (msg := rec.recv(0.05)) is not None:
            frames.append((msg.timestamp, msg.arbitration_id, bytes(msg.data)))
        return frames
    finally:
        master.disconnect()
        slave.disconnect()
        rec.shutdown()


@pytest.mark.parametrize("with_eds", [False, True])
@pytest.mark.slow
def test_canopen_pdo_api_mapping_is_followed(with_eds):
    eds = str(real_file("christiansandberg__canopen/sample.eds"))
    frames = _record_configuration(eds, f"cananalyze-net-{with_eds}")
    assert any(cob == 0x1A2 for _, cob, _ in frames), "the local node sent no PDO on the new COB-ID"
    spec = NetworkSpec({2: NodeSpec(load_eds(eds, 2), "user --eds")}) if with_eds else NetworkSpec()
    model = NetworkModel(spec)
    decoder = Decoder([SdoProcessor(), model, PdoDecoder(model)])
    model.attach(decoder)
    batch = decoder.decode(from_rows(frames))
    blocks = [b for b in batch.signals if b.cob_id == 0x1A2]
    assert len(blocks) == 1 and blocks[0].node == 2 and blocks[0].pdo == "tpdo1"
    values = {k: v.tolist() for k, v in blocks[0].columns.items()}
    if with_eds:
        assert values == {"integer16_value": [-1234], "integer32_value": [70000]}
    else:  # without a dictionary the types are unknown: raw unsigned values of the mapped widths
        assert values == {"obj_2001_00": [(-1234) & 0xFFFF], "obj_2004_00": [70000]}
    cfg = model.config_at(2)
    state = cfg.pdos[("tx", 1)]
    assert state.cob_id == 0x1A2 and state.valid and state.transmission_type == 254
    row = int(blocks[0].rows[0])
    assert (
        row_fields(batch, row)["signals"] == {k: v[0] for k, v in values.items()}
        and batch.node[row] == 2
    )
