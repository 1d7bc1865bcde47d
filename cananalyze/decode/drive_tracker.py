"""DriveTracker: each CiA 402 axis's state machine over time, from the words in the log.

Statuswords (0x6041) tell the state, controlwords (0x6040) the command, wherever they
appear: a PDO signal (the default TPDO1/RPDO1 or any remap) or an SDO read or write.
The words are named by table lookups over the signal columns (`cia402.state_codes`);
Python touches only the rows where a state or a command changes, which are rare. The
changes go on the batch (`DecodedBatch.drive`) for the event log, the outputs and the
drive rules.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cananalyze.core.records import DecodedBatch
from cananalyze.decode.model import NetworkModel, sdo_value
from cananalyze.devices import cia402
from cananalyze.protocol.services import Service

STATE, COMMAND, RESET, SEEN = "state", "command", "reset", "seen"
_OBJECTS = np.array([cia402.STATUSWORD, cia402.CONTROLWORD], np.int64)


class DriveChange(NamedTuple):
    """A drive entering a state (kind "state"), receiving a new command ("command"),
    being reset (boot-up, NMT reset: its state machine starts again), or its last
    statusword of a batch ("seen": the state still held then, for the command rule)."""

    t: float
    node: int
    row: int  # row of the frame in the batch (len(batch) for the end)
    kind: str
    code: int  # cia402 state or command code (-1 for a reset)
    word: int  # the statusword or controlword
    source: str  # "tpdo1", "rpdo1", "sdo"
    cob_id: int = 0  # the PDO's COB-ID (0: SDO or reset)
    bus: str | None = None  # a log of several buses: which one's drive (pipeline.merge_buses)

    @property
    def name(self) -> str:
        if self.kind == STATE:
            return cia402.STATE_NAMES[self.code]
        if self.kind == COMMAND:
            return cia402.COMMAND_NAMES[self.code]
        return "reset"

    def text(self) -> str:
        """The event-log line: "node 3: drive state fault (statusword 0x0618: ...)"."""
        if self.kind == STATE:
            flags = [n for bit, n in cia402.STATUS_FLAGS if self.word >> bit & 1]
            extra = f": {', '.join(flags)}" if flags else ""
            return (
                f"node {self.node}: drive state {self.name} (statusword 0x{self.word:04X}{extra})"
            )
        if self.kind == COMMAND:
            return f"node {self.node}: drive command {self.name} (controlword 0x{self.word:04X})"
        return f"node {self.node}: drive state machine restarts ({self.source})"


class DriveTracker:
    """Processor after the PDO decoder: the drive changes of each batch, state kept per node."""

    def __init__(self, model: NetworkModel) -> None:
        self.model = model
        self.state: dict[int, int] = {}  # node -> last state code
        self.command: dict[int, int] = {}  # node -> last command code

    def process(self, batch: DecodedBatch) -> None:
        obs = self._observations(batch)
        if not obs:
            return
        obs.sort(key=lambda o: (o[0], o[1]))  # (row, order within the row)
        out = batch.drive
        for row, _, node, kind, word, source, t, cob in obs:
            if kind == SEEN:
                if node in self.state:
                    out.append(DriveChange(t, node, row, SEEN, self.state[node], word, source, cob))
                continue
            if kind == RESET:
                self.state.pop(node, None)
                self.command.pop(node, None)
                out.append(DriveChange(t, node, row, RESET, -1, 0, source))
                continue
            if kind == STATE:
                code = int(cia402.STATE_OF[word & 0x7F])
                if self.state.get(node) != code:
                    self.state[node] = code
                    out.append(DriveChange(t, node, row, STATE, code, word, source, cob))
                continue
            code = int(cia402.COMMAND_OF[word & 0xFF])
            if code == cia402.SWITCH_ON and self.state.get(node) == cia402.OPERATION_ENABLED:
                code = cia402.DISABLE_OPERATION
            if self.command.get(node) != code:
                self.command[node] = code
                out.append(DriveChange(t, node, row, COMMAND, code, word, source, cob))

    def finish(self, batch: DecodedBatch) -> None:
        pass

    def _observations(self, batch: DecodedBatch) -> list[tuple]:
        """(row, order, node, kind, word, source, t) of the words that may change something:
        per signal column only the rows whose state (or command) differs from the row
        before, found with numpy."""
        fb = batch.frames
        obs: list[tuple] = []
        for sb in batch.signals:
            if not sb.words:
                continue
            for name, index in sb.words.items():
                if index not in (cia402.STATUSWORD, cia402.CONTROLWORD):
                    continue
                words = np.asarray(sb.columns[name]).astype(np.int64)
                if index == cia402.STATUSWORD:
                    code, kind = cia402.state_codes(words), STATE
                else:
                    code, kind = cia402.command_codes(words), COMMAND
                keep = np.ones(code.size, bool)
                keep[1:] = code[1:] != code[:-1]  # rows in order within a block
                # the bit 7 edge of a fault reset, and 0x07's two meanings, need every
                # change of the word itself as well
                if kind == COMMAND:
                    keep[1:] |= words[1:] != words[:-1]
                at = np.flatnonzero(keep)
                rows = sb.rows[at]
                obs += [
                    (r, 1, sb.node, kind, w, sb.pdo, t, sb.cob_id)
                    for r, w, t in zip(
                        rows.tolist(), words[at].tolist(), fb.t[rows].tolist(), strict=True
                    )
                ]
                if kind == STATE:  # the block's last statusword: the state still held
                    r = int(sb.rows[-1])
                    obs.append((r, 2, sb.node, SEEN, int(words[-1]), sb.pdo, float(fb.t[r]), 0))
        obs += self._sdo_observations(batch)
        if obs:
            obs += self._resets(batch)
        return obs

    def _sdo_observations(self, batch: DecodedBatch) -> list[tuple]:
        """Statusword reads and controlword writes by SDO on CiA 402 nodes."""
        records = batch.records
        if not records or not any(self.model.family(n) == 402 for n in self.model.nodes):
            return []  # no drive on the bus: not a record read
        c = records.cols
        picked = records.picked(np.flatnonzero(c.ok & np.isin(c.index, _OBJECTS)).tolist())
        out = []
        last: dict[int, tuple] = {}
        for row, rec in picked:
            if rec.get("kind") != "sdo" or rec.get("result") != "ok":
                continue
            index, node = rec.get("index"), rec.get("node")
            upload = rec.get("direction") == "upload"
            if (index, upload) not in ((cia402.STATUSWORD, True), (cia402.CONTROLWORD, False)):
                continue
            if rec.get("subindex") != 0 or self.model.family(node) != 402:
                continue
            value = sdo_value(rec)
            if not isinstance(value, int):
                continue
            kind = STATE if upload else COMMAND
            obs = (row, 0, node, kind, value & 0xFFFF, "sdo", float(rec.get("t") or 0.0), 0)
            out.append(obs)
            if upload:
                last[node] = obs
        # each node's last statusword read: the state still held then (for the command rule)
        out += [(o[0], 2, o[2], SEEN, *o[4:]) for o in last.values()]
        return out

    def _resets(self, batch: DecodedBatch) -> list[tuple]:
        svc = batch.service
        if not ((svc == Service.BOOTUP) | (svc == Service.NMT)).any():
            return []
        out = []
        for row, (t, node, kind) in self.model.resets_in(batch):
            for n in [node] if node else sorted(self.state):
                out.append((row, -1, n, RESET, 0, kind, t, 0))
        return out
