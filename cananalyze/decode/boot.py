"""Each node's boot story, as CiA 302-2's boot-up of a slave runs it, and where it stopped.

A boot-up message starts a story (a life of the node). Its steps, from the log: the
identity the master read (0x1000, 0x1018:01-04) against what the user declared for
the node (its profile's device type, vendor-ID and product code: `--device`, `--eds`,
the network file), the configuration written (SDO downloads; their aborts), a program
download (0x1F50/0x1F51), error control started (the first heartbeat or guard answer),
and the NMT start (a start command to the node or to all, or the node reporting
operational). A story that ends without the node operational stopped at its first
failed or missing step, which is given CiA 302-2's boot error status (A-O, as
CANopenNode's CO_BootUp.h and lely name them) where one fits. A node first seen
operational without a boot-up in the log is status L ("initially operational"), which is
no fault.

Errors on the way do not stop a node the master started anyway: they stay in its story.
`cananalyze boot`, `load().boot` and the `boot` rule read `stories()`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.protocol import nmt
from cananalyze.protocol.services import Service

STATUS = {
    "B": "no answer to the upload of the device type (0x1000)",
    "C": "device type (0x1000) differs from the expected one (0x1F84)",
    "D": "vendor-ID (0x1018:01) differs from the expected one (0x1F85)",
    "F": "no answer to node guarding",
    "I": "program download failed (0x1F50/0x1F51)",
    "J": "configuration download failed",
    "K": "no heartbeat although the node is a heartbeat producer (start error control)",
    "L": "the node was initially operational",
    "M": "product code (0x1018:02) differs from the expected one (0x1F86)",
    "N": "revision number (0x1018:03) differs from the expected one (0x1F87)",
    "O": "serial number (0x1018:04) differs from the expected one (0x1F88)",
}
# identity object -> (name, status when it differs, profile attribute expected)
IDENTITY = {
    (0x1000, 0): ("device type", "C", "device_type"),
    (0x1018, 1): ("vendor-ID", "D", "vendor_id"),
    (0x1018, 2): ("product code", "M", "product_code"),
    (0x1018, 3): ("revision number", "N", None),
    (0x1018, 4): ("serial number", "O", None),
}
PROGRAM = (0x1F50, 0x1F51)
NO_START_S = 2.0  # a life shorter than this (a reboot, the log's end) is not "not started"


@dataclass
class Story:
    node: int
    life: int  # boot-ups of the node so far (0: seen before any boot-up)
    t_boot: float | None
    steps: list = field(default_factory=list)  # (t, step, result, detail)
    identity: dict = field(default_factory=dict)  # (index, sub) -> (t, value or None)
    aborts: list = field(default_factory=list)  # (t, index, sub, what, code text)
    program: list = field(default_factory=list)
    writes: int = 0
    t_error_control: float | None = None
    t_start: float | None = None  # NMT start sent, or the node said operational
    operational: bool = False
    guard_requests: int = 0
    guard_answers: int = 0
    t_end: float | None = None  # the next boot-up (None: the story runs to the log's end)
    status: str | None = None  # CiA 302-2 letter
    stopped_at: str | None = None  # the step, in words
    verdict: str = ""

    @property
    def result(self) -> str:
        """operational (reported), started (NMT start sent, no state reported), stopped,
        or unknown (no boot-up in the log)."""
        if self.t_boot is None or (
            self.stopped_at is None and not self.verdict.startswith(("operational", "started"))
        ):
            return "operational" if self.operational else "unknown"
        if self.operational:
            return "operational"
        return "started" if self.stopped_at is None else "stopped"

    def as_row(self) -> dict:
        return {
            "node": self.node,
            "life": self.life,
            "t_boot": self.t_boot,
            "result": self.result,
            "stopped_at": self.stopped_at,
            "status": self.status,
            "status_text": STATUS.get(self.status or "", None),
            "verdict": self.verdict,
            "steps": "; ".join(f"{step}: {result}" for _, step, result, _ in self.steps),
        }


# heartbeat, boot-up, guard request and guard response: Service 9..12, one range
_NMT, _HEARTBEAT, _BOOTUP = int(Service.NMT), int(Service.HEARTBEAT), int(Service.BOOTUP)
_GUARD_RESPONSE = int(Service.GUARD_RESPONSE)


def _range_rows(svc: np.ndarray, lo: int, hi: int, other: int) -> np.ndarray:
    """The rows whose service is lo..hi or `other`: a range test in two passes (uint8
    codes wrap below lo), not a comparison per code."""
    if svc.dtype == np.uint8:
        mask = (svc - np.uint8(lo)) <= np.uint8(hi - lo)
    else:
        mask = (svc >= lo) & (svc <= hi)
    mask |= svc == other
    return np.flatnonzero(mask)


class BootFollower:
    """Follows every node's boot story batch by batch; `stories(...)` judges them."""

    def __init__(self) -> None:
        self.current: dict[int, Story] = {}
        self.done: list[Story] = []
        self.t_last: float | None = None

    def add(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        if len(fb):
            self.t_last = float(fb.t[-1])
        recs = batch.records
        # the rows a story reads depend on the batch alone: a run's two followers (the
        # commissioning processor's and the boot rule's) pick them once
        seen = batch.__dict__.get("_boot_events")
        n_recs = len(recs) if recs else 0
        if seen is not None and seen[0] == n_recs:
            events = seen[1]
        else:
            events = _events(batch)
            batch.__dict__["_boot_events"] = (n_recs, events)
        for row, what in events:
            if what:
                self._sdo(recs.record(what - 1))
            else:
                self._frame(batch, row)

    def _story(self, node: int, t: float) -> Story:
        s = self.current.get(node)
        if s is None:
            s = self.current[node] = Story(node, 0, None)
        return s

    def _frame(self, batch: DecodedBatch, row: int) -> None:
        fb = batch.frames
        t, svc, node = float(fb.t[row]), batch.service[row], int(batch.node[row])
        if svc == Service.BOOTUP:
            old = self.current.pop(node, None)
            if old is not None:
                old.t_end = t
                self.done.append(old)
            life = (old.life if old else 0) + 1
            s = self.current[node] = Story(node, life, t)
            s.steps.append((t, "boot-up", "seen", ""))
        elif svc == Service.HEARTBEAT:
            self._reported(self._story(node, t), t, "heartbeat", int(fb.data[row, 0]))
        elif svc == Service.GUARD_REQUEST:
            self._story(node, t).guard_requests += 1
        elif svc == Service.GUARD_RESPONSE:
            s = self._story(node, t)
            s.guard_answers += 1
            self._reported(s, t, "guarding", int(fb.data[row, 0]))
        elif svc == Service.NMT and fb.dlc[row] >= 2 and fb.data[row, 0] == nmt.START:
            target = int(fb.data[row, 1])
            for n, s in self.current.items():
                if (target in (0, n)) and s.t_start is None:
                    s.t_start = t
                    s.steps.append((t, "NMT start", "sent", "to all" if target == 0 else ""))

    @staticmethod
    def _reported(s: Story, t: float, via: str, byte: int) -> None:
        """A state the node reported (heartbeat or guard answer): error control has
        started; operational ends its boot (L when no boot-up or start came before)."""
        if s.t_error_control is None:
            s.t_error_control = t
            s.steps.append((t, "error control", via, ""))
        if (byte & nmt.STATE_MASK) == nmt.OPERATIONAL and not s.operational:
            s.operational = True
            if s.t_boot is None and s.t_start is None:
                s.status = "L"
            s.t_start = s.t_start or t
            s.steps.append((t, "operational", "reported", ""))

    def _sdo(self, rec: dict) -> None:
        node = rec.get("node")
        if not isinstance(node, int):
            return
        t = rec.get("t") or 0.0
        s = self._story(node, t)
        if s.operational:
            return  # the node runs: later transfers are its operation, not its boot
        key = (rec.get("index"), rec.get("subindex"))
        ok = rec.get("result") == "ok"
        upload = rec.get("direction") == "upload"
        if upload and key in IDENTITY and key not in s.identity:
            s.identity[key] = (t, rec.get("value") if ok else None)
            name = IDENTITY[key][0]
            s.steps.append((t, f"identity: {name}", _shown(rec) if ok else _abort(rec), ""))
        elif not upload and key[0] in PROGRAM:
            s.program.append((t, key, ok, _abort(rec)))
            s.steps.append((t, f"program download 0x{key[0]:04X}", "ok" if ok else _abort(rec), ""))
        elif not upload:
            if ok:
                s.writes += 1
            else:
                s.aborts.append((t, key, _abort(rec)))
                s.steps.append((t, f"configuration 0x{key[0]:04X}:{key[1]:02X}", _abort(rec), ""))

    def stories(
        self, expected=None, heartbeat_ms=None, t_end: float | None = None, timed: bool = True
    ) -> list[Story]:
        """Every story, judged: `expected(node)` the declared identity ({attr: value}) or
        None; `heartbeat_ms(node, t)` the producer time in force (None: unknown); `timed`
        False: the log has no times, so how long a node went unstarted is not known."""
        out = []
        for s in [*self.done, *self.current.values()]:
            end = s.t_end if s.t_end is not None else (t_end or self.t_last)
            _judge(s, expected(s.node) if expected else None, heartbeat_ms, end if timed else None)
            out.append(s)
        return sorted(out, key=lambda s: (s.node, s.life))


def _events(batch: DecodedBatch) -> list[tuple[int, int]]:
    """(row, 0) of the frames a boot story reads and (row, 1 + position) of the SDO
    records, in row order: boot-ups, NMT commands, guarding, a node's first heartbeat
    (and its first after each boot-up) and its first operational one in each life."""
    fb = batch.frames
    svc, node = batch.service, batch.node
    # one scan of the batch (heartbeat, boot-up and guarding are one range of codes),
    # then the few rows found are told apart
    near = _range_rows(svc, _HEARTBEAT, _GUARD_RESPONSE, _NMT)
    s = svc[near]
    is_beat = s == _HEARTBEAT
    wanted = ~is_beat  # boot-ups, NMT commands, guarding: every one
    # heartbeats: only a node's first after a boot-up, and operational reports
    beats = near[is_beat]
    if beats.size:
        state = fb.data[:, 0][beats] & nmt.STATE_MASK  # (2-D fancy indexing: ~10x)
        beat_node = node[beats]
        first = np.unique(beat_node, return_index=True)[1]
        keep = np.zeros(beats.size, bool)
        keep[first] = True
        # a node's life: the boot-ups of the node before the beat, in this batch
        life = np.zeros(beats.size, np.int64)
        for r in near[s == _BOOTUP].tolist():  # the first after each
            later = (beats > r) & (beat_node == node[r])
            after = np.flatnonzero(later)
            keep[after[:1]] = True
            life += later
        # operational reports: only the first of each node's life in this batch (once
        # a story is operational, a later report changes nothing in it)
        op = np.flatnonzero(state == nmt.OPERATIONAL)
        if op.size:
            lives = int(life.max()) + 1
            key = beat_node[op].astype(np.int64) * lives + life[op]
            if lives <= 255 and int(beat_node[op].max()) <= 127:  # 16 bits: a radix sort
                key = key.astype(np.int16)
            keep[op[np.unique(key, return_index=True)[1]]] = True
        wanted[np.flatnonzero(is_beat)[keep]] = True
    rows = near[wanted]  # in row order, as `near`
    events = [(int(r), 0) for r in rows.tolist()]
    recs = batch.records
    if recs:
        c = recs.cols
        idx = ((c.index == 0x1000) | (c.index == 0x1018)) & c.upload
        pick = np.flatnonzero((~c.ok | ~c.upload | idx) & (c.node >= 0) & (c.index >= 0))
        events += [(recs.rows[int(k)], 1 + int(k)) for k in pick.tolist()]
    return sorted(events)


def declared_identity(model, node: int) -> dict | None:
    """The identity the user declared for a node (the profile given by `--device`,
    `--eds` or the network file), or None (one identified from the log's own reads
    cannot be what the reads are checked against)."""
    from cananalyze.decode.model import USER_SOURCES

    cfg = getattr(model, "nodes", {}).get(node)
    if cfg is None or cfg.profile is None or cfg.identified_by not in USER_SOURCES:
        return None
    p = cfg.profile
    return {"device_type": p.device_type, "vendor_id": p.vendor_id, "product_code": p.product_code}


def lines(story: Story, t0: float) -> list[str]:
    """A story as `cananalyze boot` prints it: its steps by time, then the verdict."""
    head = f"node {story.node}"
    if story.t_boot is not None:
        head += f", boot-up {story.life} at {story.t_boot - t0:+.3f} s"
    out = [head + ":"]
    for t, step, result, detail in story.steps:
        out.append(f"  {t - t0:+.3f} s {step}: {result}" + (f" ({detail})" if detail else ""))
    if story.writes or story.aborts:
        out.append(f"  configuration: {story.writes} writes ok, {len(story.aborts)} aborted")
    out.append(f"  => {story.verdict}")
    return out


def _shown(rec: dict) -> str:
    v = rec.get("value")
    return f"0x{v:08X}" if isinstance(v, int) else str(v)


def _abort(rec: dict) -> str:
    if rec.get("result") == "ok":
        return "ok"
    code, text = rec.get("abort_code"), rec.get("abort_text")
    code = f"0x{code:08X}" if isinstance(code, int) else str(code or rec.get("result"))
    return f"aborted {code}" + (f" ({text})" if text else "")


def _judge(s: Story, expected: dict | None, heartbeat_ms, t_end) -> None:
    """The step a story stopped at and its CiA 302-2 status; errors of a node that was
    started anyway are kept as its verdict's remarks."""
    problems: list[tuple[str, str, str]] = []  # (status, step, words)
    dtype = s.identity.get((0x1000, 0))
    if dtype is not None and dtype[1] is None:
        problems.append(("B", "identity", "the device type read was not answered"))
    for key, (name, letter, attr) in IDENTITY.items():
        got = s.identity.get(key)
        want = (expected or {}).get(attr) if attr else None
        if got is not None and got[1] is not None and want and got[1] != want:
            problems.append((letter, "identity", f"{name} 0x{got[1]:X}, expected 0x{want:X}"))
    bad_program = [p for p in s.program if not p[2]]
    if bad_program:
        t, key, _, why = bad_program[0]
        problems.append(("I", "program download", f"0x{key[0]:04X}:{key[1]:02X} {why}"))
    if s.aborts:
        t, key, why = s.aborts[0]
        more = f" (and {len(s.aborts) - 1} more)" if len(s.aborts) > 1 else ""
        problems.append(("J", "configuration", f"0x{key[0]:04X}:{key[1]:02X} {why}{more}"))
    if s.t_boot is not None and s.t_error_control is None and heartbeat_ms is not None:
        # the producer time in force in this life (just before it ended), not a later one
        hb = heartbeat_ms(s.node, max(s.t_boot, (t_end or s.t_boot) - 1e-6))
        if hb and t_end is not None and t_end - s.t_boot > 3 * hb / 1000:
            problems.append(("K", "error control", f"no heartbeat, 0x1017 is {hb:g} ms"))
    if s.guard_requests >= 3 and not s.guard_answers:
        problems.append(("F", "error control", f"{s.guard_requests} guard requests unanswered"))
    if s.t_boot is None:
        s.verdict = (
            f"operational when the log begins (no boot-up seen: CiA 302-2 L, {STATUS['L']})"
            if s.status == "L"
            else "no boot-up in the log"
        )
        return
    started = s.t_start is not None and not any(p[0] in "FK" for p in problems)
    if s.operational or started:  # the master started it: what went wrong did not stop it
        s.stopped_at = None
        remarks = "; ".join(f"{p[2]} ({p[0]})" for p in problems)
        head = (
            "operational"
            if s.operational
            else ("started (NMT start sent; no heartbeat or guard answer tells its state)")
        )
        s.verdict = head + (f", despite: {remarks}" if remarks else "")
        return
    if problems:
        letter, step, words = problems[0]
        s.status, s.stopped_at = letter, step
        s.verdict = f"stopped at {step}: {words} (CiA 302-2 error {letter}: {STATUS[letter]})"
    elif t_end is None or t_end - s.t_boot < NO_START_S:
        s.verdict = (
            f"rebooted or the log ended within {NO_START_S:g} s: not judged"
            if t_end is not None
            else "no NMT start in the log (no times: not judged)"
        )
    else:
        s.stopped_at = "NMT start"
        s.verdict = "not started: no NMT start to the node in the log"
