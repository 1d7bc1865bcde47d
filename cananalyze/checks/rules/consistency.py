"""Does the network's configuration contradict itself? (issue 40 item 4)

Judged on the configuration in force at each moment (the values the log's SDO
transfers showed, over the user's declarations and the profiles' defaults), at the
start and again at every change of a communication object or reset. A contradiction
is reported once, when it began (the moment the later of its values took effect); a
change that resolves it ends it. One that brings it back with other objects or values
is a new one, reported; the same objects with the same values are the one already told
(a master that configures a rebooting node again each time would repeat it per boot):

- two producers on one COB-ID (TPDOs, EMCY, SYNC, TIME), or an EMCY COB-ID that is
  also an RPDO's: both transmit at once sooner or later (CANopenNode #72, EMCY 0x8150);
  and, seen on the wire, a node's TPDO or EMCY configured on the predefined COB-ID of
  another node that is on the bus and whose own PDO nothing moves elsewhere;
- a TPDO's mapped length against an RPDO on its COB-ID (EMCY 0x8210 shorter, 0x8220
  longer);
- a heartbeat consumer time (0x1016) not longer than the producer time (0x1017) it
  watches, by the rules' tolerance and jitter floor (CiA 301: consumer > producer);
- two SYNC producers (0x1005 bit 30) or two TIME producers (0x1012 bit 30);
- at the end: a consumer entry watching a node that sent no heartbeat in the whole log,
  though the entry was in force for three consumer times of traffic.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cananalyze.checks.rule import Context, Rule
from cananalyze.config.timeline import EVERY_NODE
from cananalyze.protocol.pdo_map import COB_ID_INVALID, split_cob_id
from cananalyze.protocol.services import Service

PRODUCES = 0x40000000  # bit 30 of 0x1005 (generates SYNC) and 0x1012 (produces TIME)
WATCH_PERIODS = 3  # consumer times of traffic a never-heard producer must have had

_WHY_COB = (
    "Two producers configured on one COB-ID (two nodes, or two objects of one): you will not "
    "notice until both transmit at once, then frames collide or one is taken for the other "
    "(EMCY 0x8150); give each its own COB-ID."
)
_WHY_LEN = (
    "An RPDO takes the frames of the TPDO on its COB-ID: a frame shorter than its mapping is "
    "not processed (EMCY 0x8210), a longer one may be refused (0x8220); map the same length "
    "on both sides."
)
_WHY_HB = (
    "CiA 301 asks for a consumer time longer than the producer time it watches: one at or "
    "under it expires on a heartbeat that is merely on time, with a little jitter."
)
_WHY_SILENT = (
    "A consumer watches a node that never sent a heartbeat: the node is absent, its 0x1017 "
    "is 0 or the entry names the wrong node-ID (CiA 301 monitors from the first heartbeat, "
    "so the consumer never notices)."
)
_WHY_PRODUCER = (
    "One SYNC (TIME) producer per network: two send interleaved or colliding SYNC (TIME) "
    "frames and synchronous PDOs follow both; clear bit 30 of 0x1005 (0x1012) on one."
)


class Claim(NamedTuple):
    """One object that claims a COB-ID: who, what, and where its value came from."""

    node: int
    what: str  # "TPDO1", "RPDO2", "EMCY", "SYNC producer", "TIME producer"
    index: int
    sub: int
    produces: bool

    def key(self) -> tuple[int, int, int]:
        return self.node, self.index, self.sub


class Found(NamedTuple):
    """A contradiction in force at one moment, ready to be told."""

    severity: str
    node: int | None
    cob_id: int | None
    message: str
    measured: object
    expected: object
    why: str
    basis: str


class View(NamedTuple):
    """What one node's configuration claims at one moment."""

    claims: list[tuple[tuple[int, bool], Claim]]  # (COB-ID, 29-bit) -> the object
    producers: dict[str, Claim]  # "SYNC" / "TIME": the 0x1005 / 0x1012 that sets bit 30
    lengths: dict[int, int | None]  # valid PDO's communication index -> mapped bytes
    consumers: dict[int, float]  # 0x1016: producer -> consumer time (ms)
    period: float | None  # 0x1017 (ms)
    said: frozenset[int]  # the COB-ID objects (0x1800.., 0x1014) anything gives a value for


class ConsistencyRule(Rule):
    name = "consistency"
    severity = "error"
    why = _WHY_COB
    # judged by the order of the configuration's changes: kept on logs without timestamps
    # (but for the silent producer, which needs time: three consumer times of traffic)
    timing = False

    def __init__(self, **kw) -> None:
        super().__init__(**kw)
        self.active: dict[tuple, Found] = {}  # the contradictions in force
        self.told: set[tuple] = set()  # every contradiction reported (objects and values)
        self.done: float | None = None  # configuration judged up to this time
        self.heard: set[int] = set()  # nodes that sent a heartbeat
        self.on_bus: dict[int, float] = {}  # node -> its first heartbeat or boot-up
        # (consumer, producer, consumer ms) -> start of the stretch it is in force
        self.watching: dict[tuple[int, int, float], float] = {}
        self.stretches: list[tuple[int, int, float, float, float]] = []  # + start, end
        self._view: dict[int, View] = {}  # node -> its configuration when last read
        self._cursor = 0  # the configuration's change points taken so far
        self._pending: list[tuple[float, int, int]] = []  # ... in time order
        self._taken = 0  # ... of which the first this many are judged

    def process(self, ctx: Context) -> None:
        if len(ctx.batch) == 0:
            return
        rows = ctx.rows(Service.HEARTBEAT)
        if rows.size:
            self.heard.update(np.unique(ctx.batch.node[rows]).tolist())
        rows = ctx.rows(Service.HEARTBEAT, Service.BOOTUP)
        nodes, first = np.unique(ctx.batch.node[rows], return_index=True)
        arrived = []
        for node, row in zip(nodes.tolist(), rows[first].tolist(), strict=True):
            if node not in self.on_bus and 1 <= node <= 127:
                self.on_bus[node] = float(ctx.t[row])
                arrived.append(self.on_bus[node])
        self._judge_until(ctx, float(ctx.t[-1]), arrived)

    def finish(self, ctx: Context) -> None:
        end = ctx.t_end if ctx.t_end is not None else self.done
        if end is None:
            return
        self._judge_until(ctx, end)
        if not ctx.timed:
            return
        for (consumer, producer, limit), start in self.watching.items():
            self.stretches.append((consumer, producer, limit, start, end))
        self.watching = {}
        told: set[tuple[int, int]] = set()
        for consumer, producer, limit, start, stop in self.stretches:
            if producer in self.heard or (consumer, producer) in told:
                continue
            if stop - start < WATCH_PERIODS * limit / 1000.0:
                continue
            told.add((consumer, producer))
            self._silent(ctx, consumer, producer, limit, start, stop)

    def _silent(self, ctx, consumer: int, producer: int, limit: float, start, stop) -> None:
        """A consumer entry whose producer sent no heartbeat in the whole log."""
        period = ctx.config.heartbeat_ms(producer, start)
        off = " (its 0x1017 is 0)" if period == 0 else ""
        self.emit(
            start,
            consumer,
            0x700 + producer,
            f"node {consumer}'s heartbeat consumer watches node {producer} ({limit:g} ms) but "
            f"node {producer} sent no heartbeat in the whole log{off}; the entry was in force "
            f"{ctx.rel(start)}..{ctx.rel(stop)}",
            0,
            limit,
            why=_WHY_SILENT,
            severity="warning",
            basis=ctx.config.consumer_origin(consumer, producer, start, ctx.t0),
        )

    def _judge_until(self, ctx: Context, until: float, arrived=()) -> None:
        """Judge the configuration at the first frame, then at each change up to `until`,
        and when a node first shows itself on the bus (`arrived`: those times)."""
        points = ctx.config.changes(None, 0x1005, 0x1BFF)
        if self.done is None:
            self.done = ctx.t_first
            self._judge(ctx, ctx.t_first, wire=True)
        times = set(points[(points > self.done) & (points <= until)].tolist())
        wire = {t for t in arrived if self.done < t <= until}
        for t in sorted(times | wire):
            self._judge(ctx, t, wire=t in wire)
        self.done = max(self.done, until)

    def _judge(self, ctx: Context, t: float, wire: bool = False) -> None:
        """The contradictions in force at t: the new ones told, the resolved ones ended
        (`wire`: a node showed itself on the bus at t)."""
        views = self._views(ctx, t)
        if views is None:
            if not wire:
                return  # no node's configuration changed: nor did its contradictions
            views = self._view
        claims: dict[tuple[int, bool], list[Claim]] = {}
        producers: dict[str, list[Claim]] = {"SYNC": [], "TIME": []}
        for view in views.values():
            for cob, c in view.claims:
                claims.setdefault(cob, []).append(c)
            for what, c in view.producers.items():
                producers[what].append(c)
        now: dict[tuple, Found] = {}
        self._collisions(ctx, t, claims, now)
        self._predefined(ctx, t, claims, views, now)
        self._lengths(ctx, t, claims, views, now)
        self._producers(ctx, t, producers, now)
        self._heartbeats(ctx, t, views, now)
        for key, f in now.items():
            if key in self.active or key in self.told:
                continue
            self.told.add(key)
            if f.node is not None:
                self.subjects.add(f.node)
            self.emit(
                t,
                f.node,
                f.cob_id,
                f.message,
                f.measured,
                f.expected,
                why=f.why,
                severity=f.severity,
                basis=f.basis,
            )
        self.active = now

    def _views(self, ctx: Context, t: float) -> dict[int, View] | None:
        """Every configured node's view at t: those whose configuration may have changed
        since they were read (a change point at or before t) read again, the others kept
        (a log of thousands of SDO writes reads one node per write, not all of them).
        None: no view changed since the last judgement."""
        fresh = ctx.config.points_from(self._cursor)
        self._cursor += len(fresh)
        if fresh:
            self._pending = sorted(self._pending[self._taken :] + fresh)
            self._taken = 0
        dirty = set()
        pending, k = self._pending, self._taken
        while k < len(pending) and pending[k][0] <= t:
            dirty.add(pending[k][1])
            k += 1
        self._taken = k
        first = not self._view
        if first or EVERY_NODE in dirty:
            dirty = set(ctx.config.configured_nodes()) | set(self._view)
        changed = first
        for node in dirty - {EVERY_NODE}:
            view = self._read(ctx, node, t)
            if self._view.get(node) != view:
                self._view[node] = view
                changed = True
        return self._view if changed else None

    def _read(self, ctx: Context, node: int, t: float) -> View:
        """What a node's configuration at t claims: COB-IDs, SYNC/TIME production, PDO
        lengths, heartbeat consumer entries and producer time."""
        cfg = ctx.config
        claims: list[tuple[tuple[int, bool], Claim]] = []
        producers: dict[str, Claim] = {}
        lengths: dict[int, int | None] = {}
        said: set[int] = set()

        def claim(value: int, c: Claim) -> bool:
            cob, valid = split_cob_id(value)
            if valid and cob:
                claims.append(((cob, bool(value & 0x20000000)), c))
            return valid and bool(cob)

        for comm, mapping, value, _ in cfg.pdo_cob_ids(node, t):
            said.add(comm)
            tx = comm >= 0x1800
            number = (comm & 0x1FF) + 1
            if claim(value, Claim(node, f"{'T' if tx else 'R'}PDO{number}", comm, 1, tx)):
                lengths[comm] = self._length(ctx, node, mapping, t)
        emcy = cfg.raw(node, 0x1014, 0, t)
        if emcy is not None:
            said.add(0x1014)
            claim(emcy, Claim(node, "EMCY", 0x1014, 0, True))
        for index, what in ((0x1005, "SYNC"), (0x1012, "TIME")):
            value = cfg.raw(node, index, 0, t)
            if value is not None and value & PRODUCES:
                c = Claim(node, f"{what} producer", index, 0, True)
                producers[what] = c
                claim(value & ~COB_ID_INVALID & ~PRODUCES, c)
        consumers = cfg.heartbeat_consumers(node, t)
        period = cfg.heartbeat_ms(node, t)
        return View(claims, producers, lengths, consumers, period, frozenset(said))

    def _told(self, ctx: Context, claims: list[Claim], t: float) -> tuple[int, str, str]:
        """(the node whose value came last, the claims named with their objects, and
        where each value came from)."""
        cfg = ctx.config
        latest = max(claims, key=lambda c: cfg.value_time(c.node, c.index, c.sub, t) or -np.inf)
        names = ", ".join(f"node {c.node}'s {c.what}" for c in claims)
        basis = "; ".join(cfg.origin(c.node, c.index, c.sub, t, ctx.t0) for c in claims)
        return latest.node, names, basis

    def _collisions(self, ctx: Context, t: float, claims, now: dict) -> None:
        for (cob, ext), on in sorted(claims.items()):
            producers = [c for c in on if c.produces]
            whats = {c.what for c in producers}
            clash = len(producers) > 1 and whats not in ({"SYNC producer"}, {"TIME producer"})
            if "EMCY" in whats and any(not c.produces for c in on):
                clash, producers = True, on  # an RPDO would take EMCY frames as data
            if not clash:
                continue
            node, names, basis = self._told(ctx, producers, t)
            ident = f"0x{cob:08X} (29-bit)" if ext else f"0x{cob:03X}"
            now[("cob", cob, ext, frozenset(c.key() for c in producers))] = Found(
                "error",
                node,
                cob,
                f"COB-ID {ident} claimed by {names}",
                len(producers),
                1,
                _WHY_COB,
                basis,
            )

    def _predefined(self, ctx: Context, t: float, claims, views, now: dict) -> None:
        """Seen on the wire: a COB-ID another node produces on in CiA 301's predefined
        connection set (TPDO1-4, EMCY), configured as this node's, while that node is on
        the bus (its heartbeat or boot-up) and nothing moves its own elsewhere."""
        for owner, since in self.on_bus.items():
            if since > t:
                continue
            view = views.get(owner)
            said = view.said if view is not None else frozenset()
            defaults = [(0x80 + owner, 0x1014, "EMCY")]
            defaults += [(0x80 + 0x100 * n + owner, 0x17FF + n, f"TPDO{n}") for n in range(1, 5)]
            for cob, index, what in defaults:
                others = [c for c in claims.get((cob, False), ()) if c.produces and c.node != owner]
                if index in said or not others:
                    continue
                node, names, basis = self._told(ctx, others, t)
                now[("wire", cob, owner, frozenset(c.key() for c in others))] = Found(
                    "warning",
                    node,
                    cob,
                    f"COB-ID 0x{cob:03X} claimed by {names} is node {owner}'s {what} in the "
                    f"predefined connection set, and node {owner} is on the bus (from "
                    f"{ctx.rel(since)}) with nothing that moves its {what} elsewhere",
                    2,
                    1,
                    _WHY_COB,
                    f"{basis}; node {owner}'s {what} 0x{cob:03X}: CiA 301 predefined",
                )

    def _length(self, ctx: Context, node: int, mapping: int, t: float) -> int | None:
        """Mapped bytes of a PDO at t (None: a count or an entry not known, or a count of
        0: CiA 301's remapping clears it while the entries are written)."""
        count = ctx.config.raw(node, mapping, 0, t)
        if not count or count > 64:
            return None
        bits = 0
        for sub in range(1, count + 1):
            word = ctx.config.raw(node, mapping, sub, t)
            if word is None:
                return None
            bits += word & 0xFF
        return (bits + 7) // 8

    def _lengths(self, ctx: Context, t: float, claims, views, now: dict) -> None:
        for (cob, _), on in sorted(claims.items()):
            tpdos = [c for c in on if c.what.startswith("TPDO")]
            rpdos = [c for c in on if c.what.startswith("RPDO")]
            if len(tpdos) != 1 or not rpdos:  # several producers: a collision already
                continue
            tx = tpdos[0]
            sent = views[tx.node].lengths.get(tx.index)
            if sent is None:
                continue
            for rx in rpdos:
                if rx.node == tx.node:
                    continue
                taken = views[rx.node].lengths.get(rx.index)
                if taken is None or taken == sent:
                    continue
                node, names, basis = self._told(ctx, [tx, rx], t)
                basis += "".join(
                    f"; {ctx.config.origin(c.node, c.index + 0x200, 0, t, ctx.t0)}"
                    for c in (tx, rx)
                )
                mapped = f"0x{tx.index + 0x200:04X}, 0x{rx.index + 0x200:04X}"
                now[("len", cob, tx.key(), rx.key(), sent, taken)] = Found(
                    "error" if sent < taken else "warning",
                    node,
                    cob,
                    f"COB-ID 0x{cob:03X}: node {tx.node}'s {tx.what} maps {sent} byte(s), node "
                    f"{rx.node}'s {rx.what} that takes it maps {taken} (mappings {mapped})",
                    sent,
                    taken,
                    _WHY_LEN,
                    basis,
                )

    def _producers(self, ctx: Context, t: float, producers, now: dict) -> None:
        for what, on in producers.items():
            if len(on) < 2:
                continue
            node, names, basis = self._told(ctx, on, t)
            now[(what, frozenset(c.key() for c in on))] = Found(
                "warning",
                node,
                None,
                f"{len(on)} {what} producers: {names} ({'0x1005' if what == 'SYNC' else '0x1012'} "
                "bit 30 set on each)",
                len(on),
                1,
                _WHY_PRODUCER,
                basis,
            )

    def _heartbeats(self, ctx: Context, t: float, views, now: dict) -> None:
        cfg = ctx.config
        watching: dict[tuple[int, int, float], float] = {}
        for consumer, view in views.items():
            for producer, limit in view.consumers.items():
                key = (consumer, producer, limit)
                watching[key] = self.watching.get(key, t)
                seen = views.get(producer)
                period = seen.period if seen is not None else cfg.heartbeat_ms(producer, t)
                if not period or limit >= self.late(period):
                    continue
                basis = (
                    f"{cfg.consumer_origin(consumer, producer, t, ctx.t0)}; "
                    f"{cfg.origin(producer, 0x1017, 0, t, ctx.t0)}"
                )
                now[("hb", consumer, producer, limit, period)] = Found(
                    "warning",
                    consumer,
                    0x700 + producer,
                    f"node {consumer}'s heartbeat consumer time for node {producer} is {limit:g} "
                    f"ms, node {producer}'s producer time is {period:g} ms: the consumer "
                    f"expires on a heartbeat on time (wants more than {self.late(period):g} ms)",
                    limit,
                    round(self.late(period), 3),
                    _WHY_HB,
                    basis,
                )
        for key, start in self.watching.items():
            if key not in watching:
                self.stretches.append((*key, start, t))
        self.watching = watching
