"""A canopen client and server on one python-can virtual bus, plus a passive recorder."""

from __future__ import annotations

import itertools
import time

import can
import canopen
from canopen.objectdictionary import ODVariable

from cananalyze.decode.sdo import SdoTracker

_channels = itertools.count()


def unique_channel(prefix: str) -> str:
    """A virtual-bus channel name no other test uses (channels are process-global)."""
    return f"cananalyze-{prefix}-{next(_channels)}-{time.monotonic_ns()}"


# python-canopen resends a request after 0.3 s without an answer (RESPONSE_TIMEOUT, MAX_RETRIES
# = 1): a stall that long on a loaded machine puts a second request and answer on the bus (seen
# twice in CI), a transfer no test here describes. Clients under test wait this long instead.
PATIENT_TIMEOUT_S = 5.0


def patient_client(node_id: int, od=None) -> canopen.RemoteNode:
    """A python-canopen RemoteNode whose SDO client does not resend under a scheduling stall."""
    remote = canopen.RemoteNode(node_id, canopen.ObjectDictionary() if od is None else od)
    remote.sdo.RESPONSE_TIMEOUT = PATIENT_TIMEOUT_S
    return remote


def variable(
    index: int, subindex: int, name: str, data_type: int, access: str = "rw", default=None
):
    var = ODVariable(name, index, subindex)
    var.data_type = data_type
    var.access_type = access
    var.default = default
    return var


def drain(recorder: can.BusABC) -> list[can.Message]:
    """Every frame the recorder saw so far (client and server sides both)."""
    frames = []
    while (msg := recorder.recv(timeout=0.05)) is not None:
        frames.append(msg)
    return frames


def track(frames: list[can.Message], tracker: SdoTracker) -> list:
    for ref, msg in enumerate(frames):
        tracker.feed(msg.timestamp, msg.arbitration_id, bytes(msg.data), ref)
    tracker.finish()
    return tracker.pop_completed()


def od_info(od: canopen.ObjectDictionary):
    """object_info callable for SdoTracker, from a canopen object dictionary."""

    def info(node: int, index: int, subindex: int):
        try:
            obj = od.get_variable(index, subindex)
        except KeyError:
            return None
        if obj is None:
            return None
        return obj.name, obj.data_type

    return info


def sdo_download_frames(
    node_id: int,
    od: canopen.ObjectDictionary,
    writes: list[tuple[int, int, int, int]],
    expedited: bool = True,
) -> list[list[tuple[int, bytes]]]:
    """python-canopen's SDO client writes each (index, sub, value, size) to a LocalNode with
    `od` over a virtual bus: each write's (COB-ID, data) frames, request and response (an
    expedited download: two; `expedited=False`: every frame of all writes, as one list).
    Untimed: the caller gives the times."""
    channel = unique_channel("download")
    server, client = canopen.Network(), canopen.Network()
    server.connect(interface="virtual", channel=channel)
    client.connect(interface="virtual", channel=channel)
    recorder = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
    try:
        server.add_node(canopen.LocalNode(node_id, od))
        remote = patient_client(node_id)
        client.add_node(remote)
        for index, sub, value, size in writes:
            remote.sdo.download(index, sub, value.to_bytes(size, "little"))
        frames = drain(recorder)
    finally:
        client.disconnect()
        server.disconnect()
        recorder.shutdown()
    out = [(m.arbitration_id, bytes(m.data)) for m in frames]
    if not expedited:
        return [out]
    assert len(out) == 2 * len(writes)  # expedited: one request, one response each
    return [out[k : k + 2] for k in range(0, len(out), 2)]
