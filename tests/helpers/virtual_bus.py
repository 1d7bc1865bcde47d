"""A canopen client and server on one python-can virtual bus, plus a passive recorder."""

from __future__ import annotations

import itertools
import time

import can
import canopen
from canopen.objectdictionary import ODVariable

from cananalyze.sdo import SdoTracker

_channels = itertools.count()


def unique_channel(prefix: str) -> str:
    """A virtual-bus channel name no other test uses (channels are process-global)."""
    return f"cananalyze-{prefix}-{next(_channels)}-{time.monotonic_ns()}"


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
