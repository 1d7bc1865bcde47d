"""Boot stories, LSS sequences and the longest burst as the outputs' events: the one
producer of them for a run.

A decoder processor: it follows every batch with a `BootFollower` and an `LssFollower`
(decode/boot, decode/lss) and puts on the batch (`DecodedBatch.commissioning`) what
they completed: each LSS step as it ends, and at the end of the log each node's boot
stories, judged as `cananalyze boot` judges them. The event log (decode/events: the MCAP
event log, the events table, `load().events`) and the JSONL lines read them there; the
HTML report reads the finished follower (`stories`, `lss_events`, `assignments`).

A node seen only operational (no boot-up in the log) has a story but no event: a log
without boot-up or LSS frames gets none, so its outputs stay as they were.

With a bitrate (--bitrate or the network file's) and times, the bus's longest burst
(frames back to back, protocol/busload.Bursts, as `decode --summary` prints it) is one
more event at the end of the log (kind `burst`, at its first frame's time), so the
events table, JSONL and the MCAP event log carry it; each bus's decoder has its own.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

from cananalyze.core.records import DecodedBatch
from cananalyze.decode.boot import BootFollower, Story, declared_identity
from cananalyze.decode.events.build import ERROR, INFO, WARNING
from cananalyze.decode.lss import LssEvent, LssFollower, identity_text
from cananalyze.protocol import lss as lss_protocol
from cananalyze.protocol.busload import Bursts, frame_bits

CONFIGURE_NODE_ID = lss_protocol.command_name(0x11)


class Commissioned(NamedTuple):
    """One boot story or LSS step on a batch: the event's fields (as `events.columns.Row`),
    the JSON record of it (`record`) and the story or step itself (`item`)."""

    t: float
    kind: str  # "boot", "lss" or "burst"
    node: int | None
    level: int
    message: str
    row: int | None  # the frame that ended it, in the batch (None: a boot story)
    record: dict
    item: Any  # Story, LssEvent or the burst's record
    bus: str | None = None  # several buses: which one
    # an LSS node-ID assignment the step made (`LssFollower.assignments`' own dict: its
    # `stored` turns true when a store succeeds later)
    assignment: dict | None = None


def lss_message(ev: LssEvent) -> str:
    text = f"LSS {ev.step}: {ev.result}"
    who = identity_text(ev.identity)
    if ev.node_id is not None:
        text += f", node-ID {ev.node_id}"
    if who:
        text += f" ({who})"
    if ev.detail:
        text += f" [{ev.detail}]"
    return text


def lss_level(ev: LssEvent) -> int:
    if ev.result.startswith("error"):
        return ERROR
    if ev.result.startswith(("no answer", "incomplete")):
        return WARNING
    return INFO


def boot_level(s: Story) -> int:
    if s.result == "stopped":
        return ERROR if s.status else WARNING
    return WARNING if "despite" in s.verdict else INFO


def lss_item(ev: LssEvent) -> Commissioned:
    return Commissioned(
        ev.t, "lss", None, lss_level(ev), lss_message(ev), ev.row, {"kind": "lss"} | ev.as_row(), ev
    )


def boot_item(s: Story) -> Commissioned:
    message = f"node {s.node}: boot-up {s.life}: {s.verdict}"
    record = {"kind": "boot"} | s.as_row()
    return Commissioned(s.t_boot or 0.0, "boot", s.node, boot_level(s), message, None, record, s)


def burst_item(rec: dict) -> Commissioned:
    """The longest burst ({frames, t_start, t_end}) as an event, in `decode --summary`'s
    words."""
    ms = (rec["t_end"] - rec["t_start"]) * 1000
    message = f"longest burst: {rec['frames']} frames back to back ({ms:.3f} ms)"
    record = {"kind": "burst", **rec, "ms": round(ms, 6)}
    return Commissioned(rec["t_start"], "burst", None, INFO, message, None, record, rec)


class _Placed(LssFollower):
    """An LssFollower whose steps name the frame that ended them: the answer, the command
    itself, or the next master frame for a command nobody answered (the command may be in
    a batch already written: the outputs place a step where it became known, whatever the
    batches)."""

    at = -1  # the LSS frame being read (a row of the batch)

    def _master(self, t: float, row: int, data: bytes) -> None:
        self.at = row
        super()._master(t, row, data)

    def _slave(self, t: float, row: int, data: bytes) -> None:
        self.at = row
        super()._slave(t, row, data)

    def _emit(self, t, row, *rest, **kw) -> None:
        super()._emit(t, self.at, *rest, **kw)


class Commissioning:
    """The decoder's processor of boot stories and LSS sequences (see the module)."""

    def __init__(
        self, model, heartbeat_ms: Callable | None = None, bitrate: int | None = None
    ) -> None:
        self.model = model
        self.bursts = Bursts(bitrate) if bitrate else None
        self.span: tuple[float, float] | None = None  # the log's earliest and latest time
        self.heartbeat_ms = heartbeat_ms  # (node, t) -> the 0x1017 in force, or None
        self.boot = BootFollower()
        self.lss = _Placed()
        self.lss_events: list[LssEvent] = []
        self.stories: list[Story] = []
        self.timed: bool | None = None  # as the checker decides: from the first 2 frames
        self.t_last: float | None = None

    @property
    def assignments(self) -> list[dict]:
        """Which identity got which node-ID by LSS, when, and whether it was stored."""
        return self.lss.assignments

    def process(self, batch: DecodedBatch) -> None:
        t = batch.frames.t
        if self.timed is None and t.size >= 2:
            self.timed = bool(t.max() > t.min())
        if t.size:
            self.t_last = float(t[-1])
            if self.bursts is not None:
                fb = batch.frames
                self.bursts.add(t, frame_bits(fb.flags, fb.dlc))
                lo, hi = float(t.min()), float(t.max())
                span = self.span
                self.span = (lo, hi) if span is None else (min(span[0], lo), max(span[1], hi))
        self.boot.add(batch)
        known = len(self.lss.assignments)
        self._lss(batch, self.lss.add(batch), known)

    def _lss(self, batch: DecodedBatch, events: list[LssEvent], known: int) -> None:
        self.lss_events += events
        made = iter(self.lss.assignments[known:])  # one per configure node-ID answered ok
        for ev in events:
            item = lss_item(ev)
            if ev.step == CONFIGURE_NODE_ID and ev.result == "ok":
                item = item._replace(assignment=next(made, None))
            batch.commissioning.append(item)

    def finish(self, batch: DecodedBatch) -> None:
        self.lss.at = len(batch)  # what only the end completes: at the end
        self._lss(batch, self.lss.finish(), len(self.lss.assignments))
        timed = self.timed is not False
        model = self.model
        self.stories = self.boot.stories(
            lambda n: declared_identity(model, n),
            self.heartbeat_ms if timed else None,
            self.t_last,
            timed=timed,
        )
        batch.commissioning.extend(boot_item(s) for s in self.stories if s.t_boot is not None)
        # as the summary judged it: a log with times (decided as the checks decide, so a
        # frame at a time, as live feeds them, is judged like one batch) and a duration
        spread = self.span is not None and self.span[1] > self.span[0]
        rec = self.bursts.record() if self.bursts is not None and timed and spread else None
        if rec is not None:
            batch.commissioning.append(burst_item(rec))
