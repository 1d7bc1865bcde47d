"""SRDO (CiA 304): each pair's inverted frame, its validation time, the refresh time, and GFC.

Judged as a consumer judges them (CANopenNode 304/CO_SRDO.c `CO_SRDO_process`, lines
866-983; protocol/srdo.py has the layout):

- the inverted frame is the exact bit inversion of the normal one, over the SRDO's data
  length (its mapping's; both frames' longer DLC while the mapping is not known);
- it follows the normal frame within SRVT (0x1301+:3), else the pair is late, or missing
  when the next normal frame comes first;
- the next normal frame follows within SCT (0x1301+:2) while the producer may send
  (operational, or its state never seen: CiA 304 sends SRDOs only when operational);
- a global fail-safe command (COB-ID 0x001) is reported as information;
- when the log writes 0x13FE (configuration valid) = 0xA5, each SRDO's CRC signature in
  0x13FF is the one its parameters in force give (CO_SRDO_config's check, CO_SRDO.c
  lines 507-533), where the log, the network file or the profile gives every value.

Each is judged with the SRDO's parameters in force at the frame (the network model's SRDO
log: SDO writes to 0x1301-0x1340 / 0x1381-0x13C0, the network file, the device's EDS);
a time of 0 (not known) is not judged. A log that starts between a pair's two frames
says nothing about the first inverted frame. Per-frame Python over SRDO rows only (two
frames per SCT per SRDO).
"""

from __future__ import annotations

import numpy as np

from cananalyze.checks.rule import Context, Rule, ms
from cananalyze.protocol import srdo as layout
from cananalyze.protocol.nmt import OPERATIONAL
from cananalyze.protocol.services import Service
from cananalyze.protocol.srdo import SrdoConfig, not_inverted

_SENDING = (OPERATIONAL, -1)


class SrdoRule(Rule):
    name = "srdo"
    timing = False  # the inversion is judged on logs without timestamps too
    why = (
        "A safety consumer drops to its safe state when an SRDO pair is not exactly inverted, "
        "its inverted frame comes later than SRVT, or no pair comes within SCT: check the "
        "producer's mapping (0x1381+), its cycle (0x1301+:2/:3) and the bus load."
    )

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        # (node, SRDO number) -> the normal frame waiting for its inverted one:
        # (t, data, dlc, row, cob), and the time of the last normal frame
        self.pending: dict[tuple[int, int], tuple[float, np.ndarray, int, int, int]] = {}
        self.last_normal: dict[tuple[int, int], float] = {}
        self.last_config: dict[
            tuple[int, int], SrdoConfig
        ] = {}  # the SRDO at its last normal frame
        self.reported: set[tuple[tuple[int, int], float]] = set()  # silences tick() reported

    def process(self, ctx: Context) -> None:
        b = ctx.batch
        fb = b.frames
        self._signatures(ctx)
        for row in ctx.rows(Service.GFC).tolist():
            self.emit(
                fb.t[row],
                None,
                int(fb.can_id[row]),
                "global fail-safe command (GFC)"
                + (f" with {int(fb.dlc[row])} data bytes (CiA 304: none)" if fb.dlc[row] else ""),
                "GFC",
                "no GFC",
                row=row,
                severity="info",
                why="A node commanded every safety device to its fail-safe state (CiA 304 GFC).",
            )
        rows = ctx.rows(Service.SRDO, Service.SRDO_INVERTED)
        if rows.size == 0:
            return
        inverted = (b.service[rows] == Service.SRDO_INVERTED).tolist()
        for row, inv in zip(rows.tolist(), inverted, strict=True):
            t = float(fb.t[row])
            cob = int(fb.can_id[row])
            found = ctx.config.srdo_params(cob, t)
            if found is None:
                continue
            config = found[0]
            key = (config.node, config.number)
            self.subjects.add(config.node)
            if inv:
                self._inverted(ctx, key, config, t, row, cob)
            else:
                self._normal(ctx, key, config, t, row, cob)

    def _normal(self, ctx: Context, key, config, t: float, row: int, cob: int) -> None:
        fb = ctx.batch.frames
        waiting = self.pending.get(key)
        name = f"SRDO{config.number}"
        if waiting is not None:
            self.emit(
                waiting[0],
                config.node,
                waiting[4],
                f"{name} normal frame without its inverted frame before the next normal one "
                f"at {ctx.rel(t)}",
                "no inverted frame",
                "the inverted frame within SRVT",
                row=waiting[3],
                basis=self._basis(ctx, config, 3, waiting[0]),
            )
        last = self.last_normal.get(key)
        told = last is not None and (key, last) in self.reported
        if (
            ctx.timed
            and last is not None
            and config.sct
            and not told
            and self._sending(ctx, config, last, t)
        ):
            gap = t - last
            if gap * 1000.0 > self.late(config.sct):
                self.emit(
                    last,
                    config.node,
                    cob,
                    f"{name}: no pair for {ms(gap)} ms, refresh time SCT {config.sct} ms",
                    ms(gap),
                    config.sct,
                    row=row,
                    basis=self._basis(ctx, config, 2, t),
                )
        self.last_normal[key] = t
        self.last_config[key] = config
        self.pending[key] = (t, fb.data[row].copy(), int(fb.dlc[row]), row, cob)

    def tick(self, ctx: Context, now: float) -> None:
        """Live: an SRDO whose next pair is overdue by its SCT while its producer may send,
        reported once (the pair that ends the silence is not reported again)."""
        for key, last in sorted(self.last_normal.items()):
            config = self.last_config[key]
            sct = config.sct
            if not sct or (key, last) in self.reported or (now - last) * 1000 <= self.late(sct):
                continue
            if not self._sending(ctx, config, last, now):
                continue
            self.reported.add((key, last))
            self.emit(
                now,
                config.node,
                config.cob_normal,
                f"SRDO{key[1]}: no pair since {ctx.rel(last)} ({ms(now - last)} ms so far), "
                f"refresh time SCT {sct} ms" + self.quiet(ctx, last + self.late(sct) / 1000.0),
                ms(now - last),
                sct,
                basis=self._basis(ctx, config, 2, last),
            )

    def _inverted(self, ctx: Context, key, config, t: float, row: int, cob: int) -> None:
        fb = ctx.batch.frames
        name = f"SRDO{config.number}"
        waiting = self.pending.pop(key, None)
        if waiting is None:
            if key in self.last_normal:  # not the log's first frame of this SRDO
                self.emit(
                    t,
                    config.node,
                    cob,
                    f"{name} inverted frame without a normal frame before it",
                    "inverted frame alone",
                    "the normal frame, then the inverted one",
                    row=row,
                )
            return
        t_normal, data, dlc, _, _ = waiting
        delay = t - t_normal
        if ctx.timed and config.srvt and delay * 1000.0 > self.late(config.srvt):
            self.emit(
                t,
                config.node,
                cob,
                f"{name} inverted frame {ms(delay)} ms after the normal one, "
                f"validation time SRVT {config.srvt} ms",
                ms(delay),
                config.srvt,
                row=row,
                basis=self._basis(ctx, config, 3, t),
            )
        length = config.data_length or max(dlc, int(fb.dlc[row]))
        length = min(length, 8)
        if not_inverted(data[None, :8], fb.data[row : row + 1, :8], np.array([length]))[0]:
            normal_hex = bytes(data[:length]).hex(" ").upper()
            inv_hex = bytes(fb.data[row, :length]).hex(" ").upper()
            self.emit(
                t,
                config.node,
                cob,
                f"{name} inverted frame {inv_hex} is not the bit inversion of the normal "
                f"frame {normal_hex}",
                inv_hex,
                bytes(b ^ 0xFF for b in data[:length]).hex(" ").upper(),
                row=row,
            )

    def _signatures(self, ctx: Context) -> None:
        """At each write of 0x13FE = 0xA5: every in-use SRDO's 0x13FF against its parameters."""
        recs = ctx.batch.records
        if not recs:
            return
        c = recs.cols
        at = np.flatnonzero(c.ok & ~c.upload & (c.index == layout.CONFIG_VALID) & (c.node >= 0))
        for i in at.tolist():
            node, t = int(c.node[i]), float(c.t[i])
            if ctx.config.raw(node, layout.CONFIG_VALID, 0, t) != layout.VALID_MAGIC:
                continue
            for number in range(1, layout.COUNT + 1):
                self._signature(ctx, node, number, t, int(c.row[i]))

    def _signature(self, ctx: Context, node: int, number: int, t: float, row: int) -> None:
        comm, mapping = layout.COMM_BASE + number - 1, layout.MAP_BASE + number - 1
        direction = ctx.config.raw(node, comm, layout.SUB_DIRECTION, t)
        if direction not in (1, 2):
            return
        subs = (layout.SUB_SCT, layout.SUB_SRVT, layout.SUB_NORMAL, layout.SUB_INVERTED)
        values = [ctx.config.raw(node, comm, sub, t) for sub in subs]
        count = ctx.config.raw(node, mapping, 0, t)
        stored = ctx.config.raw(node, layout.CRC_INDEX, number, t)
        if None in values or count is None or stored is None or count > 16:
            return
        words = [ctx.config.raw(node, mapping, sub, t) for sub in range(1, count + 1)]
        if None in words:
            return
        sct, srvt, normal, inverted = values
        want = layout.signature(node, number, direction, sct, srvt, normal, inverted, words)  # type: ignore[arg-type]
        if want == stored:
            return
        self.subjects.add(node)
        self.emit(
            t,
            node,
            None,
            f"SRDO{number} configuration signature 0x13FF:{number} is 0x{stored:04X}, its "
            f"parameters give 0x{want:04X}: the node will not run it",
            f"0x{stored:04X}",
            f"0x{want:04X}",
            row=row,
            basis=ctx.config.origin(node, layout.CRC_INDEX, number, t, ctx.t0),
        )

    @staticmethod
    def _sending(ctx: Context, config, t0: float, t1: float) -> bool:
        """Whether the producer may send SRDOs throughout a gap: operational (or its state
        never seen) at its start and in every state it entered before its end. A
        consumer's parameters alone do not say which node produces: then it may."""
        if config.direction != 1:
            return True
        node = config.node
        steady = ctx.nmt.steady_state(node, t0, t1)
        if steady is not None:
            return steady in _SENDING
        states = [int(ctx.nmt.state_at(node, np.array([t0]))[0])]
        changes = zip(ctx.nmt.times.get(node, ()), ctx.nmt.states.get(node, ()), strict=True)
        states += [int(s) for t, s in changes if t0 < t <= t1]
        return all(s in _SENDING for s in states)

    @staticmethod
    def _basis(ctx: Context, config, sub: int, t: float) -> str:
        return ctx.config.origin(config.node, 0x1301 + config.number - 1, sub, t, ctx.t0)
