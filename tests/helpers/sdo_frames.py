"""Feed frames written as the manuals print them ("40 08 10 01 00 00 00 00") to a tracker."""

from __future__ import annotations

from cananalyze.decode.sdo import FrameRole, SdoTracker


def replay(
    tracker: SdoTracker, frames: list[tuple[int, str]], t0: float = 0.0, dt: float = 0.001
) -> list[FrameRole]:
    roles = []
    for i, (cob, text) in enumerate(frames):
        roles.append(tracker.feed(t0 + i * dt, cob, bytes.fromhex(text), i))
    return roles
