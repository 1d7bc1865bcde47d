"""Test helper: a Capture of a log through the real pipeline, with the demo's devices declared."""

from __future__ import annotations

from cananalyze.capture import Capture, load

DEMO_DEVICES = {3: "mcb560", 5: "dat7014"}


def demo_capture(path, devices=None) -> Capture:
    devices = devices or DEMO_DEVICES
    return load(path, device=[f"{node}={key}" for node, key in devices.items()])
