"""LSS (CiA 305) sequences: which identity was selected, which node-ID it got, and what failed.

LSS frames are rare and each means something only with the ones around it (a fastscan
is up to 130 probes, a selective switch four commands), so they are followed one by one,
in order, like SDO transfers. A master command that expects an answer takes the first
slave frame with the answering command specifier before the next master frame; none
is "no answer". The steps become events:

- `fastscan`: the probes of one scan as one event, with the identity found (the value
  confirmed for each of the four parts, CiA 305's bitChecked = 0 probes answered), or
  "no non-configured slave" (the first probe unanswered), or where it stopped;
- `switch selective`: vendor, product, revision and serial, answered or not;
- `switch global` (to configuration or waiting), `configure node-ID`, `configure bit
  timing`, `activate bit timing`, `store configuration`, `inquire ...`, `identify ...`;
  configuration commands with the slave's error code.

A configure node-ID answered "ok" after a slave was selected (by fastscan or selective
switch) is an assignment: that identity got that node-ID; a store answered "ok" while it
is selected marks it stored. `load().lss`, `load().lss_assignments`, `decode --summary`
and the `lss` rule read these.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.protocol import lss
from cananalyze.protocol.services import Service

PARTS = ("vendor_id", "product_code", "revision", "serial")
# master command -> the slave's answering command specifier
ANSWER = {0x43: 0x44, 0x4B: 0x4F, 0x4C: 0x50, 0x51: 0x4F, 0x11: 0x11, 0x13: 0x13, 0x17: 0x17}
ANSWER |= {cs: cs for cs in range(0x5A, 0x5F)}
CONFIG_ERRORS = {
    0x11: {1: "node-ID out of range"},
    0x13: {1: "bit timing not supported"},
    0x17: {1: "store not supported", 2: "storage media access error"},
}
_SELECTIVE = range(0x40, 0x44)
_IDENTIFY = range(0x46, 0x4C)


@dataclass
class LssEvent:
    t: float
    row: int  # the frame that ended it (its last master frame or answer), in the batch
    step: str
    result: str  # "ok", "no answer", "error N: text", "found", "incomplete", ...
    identity: dict = field(default_factory=dict)  # PARTS that the step names
    node_id: int | None = None
    detail: str = ""

    def as_row(self) -> dict:
        row = {"t": self.t, "step": self.step, "result": self.result}
        row |= {p: self.identity.get(p) for p in PARTS}
        row |= {"node_id": self.node_id, "detail": self.detail}
        return row


_LSS_MASTER = int(Service.LSS_MASTER)  # and LSS_SLAVE its next code


def _is_lss(svc: np.ndarray) -> np.ndarray:
    """LSS master or slave frames: one range test (uint8 codes wrap below the first)."""
    if svc.dtype == np.uint8:
        return (svc - np.uint8(_LSS_MASTER)) <= np.uint8(1)
    return (svc == Service.LSS_MASTER) | (svc == Service.LSS_SLAVE)


class LssFollower:
    """Follows LSS frames across batches; `add` gives each batch's completed events."""

    def __init__(self) -> None:
        self.pending: tuple | None = None  # (t, row, cs, data) of a command awaiting answer
        self.selective: dict = {}  # parts of a selective switch so far
        self.scan: dict | None = None  # the fastscan in progress
        self.selected: dict | None = None  # the identity in configuration state
        self.assignments: list[dict] = []
        self._out: list[LssEvent] = []

    def add(self, batch: DecodedBatch) -> list[LssEvent]:
        fb = batch.frames
        rows = np.flatnonzero(_is_lss(batch.service))
        for r in rows.tolist():
            data = bytes(fb.data[r, : min(int(fb.dlc[r]), 8)])
            if not data:
                continue
            if batch.service[r] == Service.LSS_MASTER:
                self._master(float(fb.t[r]), r, data)
            else:
                self._slave(float(fb.t[r]), r, data)
        out, self._out = self._out, []
        return out

    def finish(self) -> list[LssEvent]:
        """The end of the log: a command still waiting has no answer."""
        self._close(None)
        if self.scan is not None:
            self._end_scan(self.scan["t"], self.scan["row"], "incomplete: the log ends")
        out, self._out = self._out, []
        return out

    # --- master and slave frames ------------------------------------------------------
    def _master(self, t: float, row: int, data: bytes) -> None:
        self._close(None)
        cs = data[0]
        if cs != 0x51 and self.scan is not None:
            self._end_scan(t, row, "incomplete: another command came")
        if cs in ANSWER:
            self.pending = (t, row, cs, data)
        if cs == 0x04:
            mode = data[1] if len(data) > 1 else None
            to = {0: "waiting", 1: "configuration"}.get(mode, f"mode {mode}")
            if mode == 0:
                self.selected = None
            self._emit(t, row, "switch state global", "sent", detail=f"to {to}")
        elif cs in _SELECTIVE and cs != 0x43:
            self.selective[PARTS[cs - 0x40]] = _u32(data)
        elif cs == 0x15:
            delay = int.from_bytes(data[1:3], "little") if len(data) >= 3 else None
            self._emit(t, row, "activate bit timing", "sent", detail=f"switch delay {delay} ms")

    def _slave(self, t: float, row: int, data: bytes) -> None:
        if self.pending is not None and data[0] == ANSWER[self.pending[2]]:
            self._close((t, row, data))

    def _close(self, answer: tuple | None) -> None:
        """The pending command answered (`answer`: t, row, data) or not (None)."""
        if self.pending is None:
            return
        t0, row0, cs, data = self.pending
        self.pending = None
        t, row = (answer[0], answer[1]) if answer else (t0, row0)
        reply = answer[2] if answer else None
        if cs == 0x51:
            self._fastscan(t, row, data, reply is not None)
        elif cs == 0x43:
            parts = self.selective | {"serial": _u32(data)}
            self.selective = {}
            if reply is not None:
                self.selected = parts
            self._emit(
                t, row, "switch state selective", "selected" if reply else "no answer", parts
            )
        elif cs in (0x11, 0x13, 0x17):
            self._configure(t, row, cs, data, reply)
        elif 0x5A <= cs <= 0x5E:
            what = lss.command_name(cs).removeprefix("inquire ")
            value = None
            if reply is not None:
                value = reply[1] if cs == 0x5E and len(reply) > 1 else _u32(reply)
            self._emit(
                t,
                row,
                lss.command_name(cs),
                "ok" if reply else "no answer",
                detail="" if value is None else f"{what} {value}",
            )
        elif cs in (0x4B, 0x4C):
            self._emit(t, row, lss.command_name(cs), "answered" if reply else "no answer")

    def _configure(self, t: float, row: int, cs: int, data: bytes, reply: bytes | None) -> None:
        step = lss.command_name(cs)
        node = data[1] if cs == 0x11 and len(data) > 1 else None
        detail = ""
        if cs == 0x13 and len(data) > 2:
            detail = f"table {data[1]}, index {data[2]}"
        if reply is None:
            result = "no answer"
        else:
            code = reply[1] if len(reply) > 1 else 0
            if code == 0:
                result = "ok"
            else:
                text = CONFIG_ERRORS.get(cs, {}).get(code)
                if code == 0xFF:
                    text = f"manufacturer error {reply[2] if len(reply) > 2 else '?'}"
                result = f"error {code}" + (f": {text}" if text else "")
        who = dict(self.selected or {})
        self._emit(t, row, step, result, who, node, detail)
        if result == "ok" and cs == 0x11:
            self.assignments.append(
                {"t": t, **{p: who.get(p) for p in PARTS}, "node_id": node, "stored": False}
            )
        if result == "ok" and cs == 0x17:
            for a in reversed(self.assignments):
                if all(a[p] == who.get(p) for p in PARTS):
                    a["stored"] = True
                    break

    def _fastscan(self, t: float, row: int, data: bytes, answered: bool) -> None:
        number, bit, sub, nxt = struct.unpack_from("<IBBB", data.ljust(8, b"\0"), 1)
        if bit == 0x80:  # the first probe: is any non-configured slave there?
            if self.scan is not None:
                self._end_scan(t, row, "incomplete: a new scan began")
            if not answered:
                self._emit(t, row, "fastscan", "no non-configured slave")
                return
            self.scan = {"t": t, "row": row, "found": {}, "probes": 1}
            return
        if self.scan is None:
            return  # a scan whose start the log does not hold
        self.scan["probes"] += 1
        # bitChecked 0 with lssNext past lssSub confirms a part (the slave's walk moves on
        # to lssNext; lssNext below lssSub: all four matched, the slave is selected); with
        # lssNext = lssSub it only probes bit 0 (unanswered: the bit is 1)
        if bit != 0 or nxt == sub or sub > 3:
            return
        if not answered:
            self._end_scan(t, row, f"incomplete: {PARTS[sub]} not confirmed")
            return
        self.scan["found"][PARTS[sub]] = number
        if nxt < sub:
            self.selected = dict(self.scan["found"])
            self._end_scan(t, row, "found")

    def _end_scan(self, t: float, row: int, result: str) -> None:
        scan, self.scan = self.scan, None
        if scan is None:
            return
        self._emit(t, row, "fastscan", result, scan["found"], detail=f"{scan['probes']} probes")

    def _emit(self, t, row, step, result, identity=None, node=None, detail="") -> None:
        self._out.append(LssEvent(t, row, step, result, dict(identity or {}), node, detail))


def _u32(data: bytes) -> int:
    return int.from_bytes(data[1:5].ljust(4, b"\0"), "little")


def identity_text(identity: dict) -> str:
    """ "vendor 0x0000004C, product 0x00000001, ..." of the parts known."""
    names = {"vendor_id": "vendor", "product_code": "product", "revision": "revision"}
    return ", ".join(
        f"{names.get(p, p)} 0x{identity[p]:08X}" for p in PARTS if identity.get(p) is not None
    )
