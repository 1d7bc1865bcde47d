"""NetworkModel: the analyser's picture of each node, kept up to date from the log.

It starts from what the user declared (profiles, network file, the rules file's
`network:`) and then follows the log in time order: completed SDO transfers (writes
and read-backs alike) of communication objects and unit-changing device objects, and
resets (boot-ups, NMT reset commands), which return a node to its declared values.
Uploads of the identity objects (0x1018, 0x1000, 0x1008) pick a built-in profile.

Two views of the same facts: the current configuration that decoding needs (PDO
bindings, kept in step with the COB-ID classifier, so a PDO moved to another COB-ID is
attributed to the right node from the frame after the write on), and `known()`, the
value of any object at any time the checks ask about (the log's values are kept in
timeline.py; the rule is docs/network-file.md, "Precedence"). Per-frame Python here
touches only SDO records and resets, which are rare.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from cananalyze.config.node_config import TOUCHES_COB_IDS, NodeConfig
from cananalyze.config.spec import NetworkSpec
from cananalyze.config.timeline import ConfigChange, Timeline
from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.node_tally import IDENTITY
from cananalyze.devices.builtin import identify
from cananalyze.protocol import srdo as srdo_layout
from cananalyze.protocol.cobid import NO_NODE, CobClassifier
from cananalyze.protocol.comm_objects import comm_object
from cananalyze.protocol.pdo_map import PdoConfig, split_cob_id
from cananalyze.protocol.services import Service
from cananalyze.protocol.srdo import SrdoConfig

NOT_VALID = (
    "is not valid (COB-ID bit 31 set)"  # PdoBinding.problem; the pdo_not_valid rule looks for it
)
_IDENTITY_INDICES = np.array([0x1018, 0x1000, 0x1008], np.int64)
USER_SOURCES = ("user --device", "user --eds", "network file", "rules file")


def generic_for(device_type) -> object:
    """The CiA 402/401 defaults for a device type naming them, else None."""
    from cananalyze.devices.family import family
    from cananalyze.devices.generic import generic_profile

    fam = family(device_type)
    return generic_profile(fam) if fam else None


@dataclass(frozen=True)
class PdoBinding:
    """Which node's PDO a COB-ID carries, with the mapping in force."""

    node: int
    kind: str  # "tpdo" / "rpdo"
    number: int
    config: PdoConfig
    problem: str | None = None  # set when frames arrive on a PDO that is not valid


class Known(NamedTuple):
    """An object's expected value and where it comes from: "log" (an SDO write or read at
    or before the time asked, since the node's last reset), "file" (the user's
    declarations) or "profile" (DCF value, else EDS default)."""

    value: int
    source: str


def sdo_value(rec: dict) -> int | str | None:
    data = rec.get("data")
    if isinstance(data, str) and data:
        try:
            raw = bytes.fromhex(data)
        except ValueError:
            raw = None
        if raw is not None:
            if (rec.get("index"), rec.get("subindex")) == (0x1008, 0):
                return raw.split(b"\0")[0].decode("latin-1").strip()
            return int.from_bytes(raw[:8], "little")
    value = rec.get("value")
    return value if isinstance(value, (int, str)) and not isinstance(value, bool) else None


class NetworkModel:
    """Per-node configuration state; a Processor that runs after the SDO tracker."""

    def __init__(
        self, spec: NetworkSpec | None = None, classifier: CobClassifier | None = None
    ) -> None:
        self.spec = spec or NetworkSpec()
        self.nodes: dict[int, NodeConfig] = {}
        self.timeline = Timeline()  # the values the log showed, and the resets
        self._early: dict[int, tuple[dict, set[int] | None]] = {}  # identify_now's, by id
        # nodes whose SRDO 1 the log showed on its default COB-IDs (`_seen_srdos`)
        self._seen_srdo: set[int] = set()
        self._file = {
            (node, index, sub): value
            for node, ns in self.spec.nodes.items()
            for index, sub, value in ns.writes
        }
        self._bus_file = {(index, sub): value for index, sub, value in self.spec.bus_writes}
        self.bindings: dict[int, PdoBinding] = {}
        self.binding_times: list[float] = []  # when the bindings changed, and to what
        self.binding_log: list[dict[int, PdoBinding]] = []
        # Bindings in force within the current batch: (first row, bindings), ascending.
        self.segments: list[tuple[int, dict[int, PdoBinding]]] = [(0, {})]
        # SRDOs in force: COB-ID -> (its SRDO, whether it is the inverted frame's), and the
        # same after every change (times ascending), for the rows and the rule's judgement
        self.srdo_bindings: dict[int, tuple[SrdoConfig, bool]] = {}
        self.srdo_times: list[float] = []
        self.srdo_log: list[dict[int, tuple[SrdoConfig, bool]]] = []
        self.classifier: CobClassifier | None = None
        self._assigned: dict[int, tuple[int, int, int]] = {}
        # (node, index, subindex) -> object_info answer; cleared when a node's profile changes
        self._info: dict[tuple[int, int, int], tuple[str, int] | None] = {}
        for node, ns in self.spec.nodes.items():
            self.nodes[node] = self._declared_config(node, ns.profile, ns.how)
        self._rebind(float("-inf"))
        if classifier is not None:
            self.bind(classifier)

    def _declared_config(self, node: int, profile, how: str) -> NodeConfig:
        """A node as declared: its profile's defaults with the user's values on top."""
        cfg = NodeConfig.from_profile(node, profile, how)
        ns = self.spec.nodes.get(node)
        if ns is not None:
            for index, sub, value in ns.writes:
                cfg.apply(index, sub, value)
            for (direction, number), length in ns.pdo_lengths.items():
                cfg.pdo(direction, number).length = length  # type: ignore[arg-type]
            cfg.sdo_channels = list(ns.sdo_channels)
            cfg.signals = ns.signals
        if node in self._seen_srdo:
            self._adopt_seen_srdo(cfg)
        return cfg

    @staticmethod
    def _adopt_seen_srdo(cfg: NodeConfig) -> bool:
        """A node's SRDO 1 as a pair on its default COB-IDs shows it: produced, its times
        not known (not judged), unless something configured it (False then)."""
        state = cfg.srdo(1)
        cobs = srdo_layout.default_cob_ids(cfg.node)
        if cobs is None or state.direction or state.cob_normal is not None:
            return False
        state.direction = 1
        state.cob_normal, state.cob_inverted = cobs
        return True

    # --- wiring ------------------------------------------------------------------
    def bind(self, classifier: CobClassifier) -> None:
        """Give the model the decoder's classifier (before the first batch is decoded)."""
        self.classifier = classifier
        self._assigned = {}
        self._sync_classifier()

    def attach(self, decoder) -> NetworkModel:
        """Joined to a decoder as one of its processors: it needs the decoder's classifier."""
        self.bind(decoder.classifier)
        return self

    @property
    def sdo_channels(self) -> list[tuple[int, int, int]]:
        """User-declared extra SDO channels: (server node, request COB-ID, response COB-ID)."""
        return [
            (n, req, resp)
            for n, cfg in sorted(self.nodes.items())
            for req, resp in cfg.sdo_channels
        ]

    # --- queries -----------------------------------------------------------------
    def object_info(self, node: int, index: int, subindex: int) -> tuple[str, int] | None:
        """(name, data type) of an object on a node: its profile, else CiA 301's common objects.

        The SDO tracker calls this to name and decode transaction values: answers are
        kept until a node's profile changes (a profile lookup costs microseconds).
        """
        key = (node, index, subindex)
        found = self._info.get(key, self._info)
        if found is not self._info:
            return found  # type: ignore[return-value]
        found = self._info[key] = self._object_info(node, index, subindex)
        return found

    def _object_info(self, node: int, index: int, subindex: int) -> tuple[str, int] | None:
        cfg = self.nodes.get(node)
        profile = cfg.profile if cfg is not None else None
        if profile is not None:
            info = profile.object(index, subindex)
            if info is not None:
                return info.name, info.datatype
        return comm_object(index, subindex)

    def family(self, node: int) -> int | None:
        """402 or 401 when the node's profile, or its device type read in the log, names
        CiA 402 (drives) or CiA 401 (I/O)."""
        from cananalyze.devices.family import family

        cfg = self.nodes.get(node)
        if cfg is None:
            return None
        if cfg.profile is not None and cfg.profile.family:
            return cfg.profile.family
        return family(cfg.identity.get("device_type"))

    def config_at(self, node: int) -> NodeConfig:
        """Current configuration of a node (an empty 'unknown' one if never seen)."""
        cfg = self.nodes.get(node)
        if cfg is None:
            cfg = self.nodes[node] = NodeConfig(node)
            self._info.clear()
        return cfg

    @property
    def history(self) -> list[ConfigChange]:
        """Every value the log showed (SDO writes and reads), in order."""
        return self.timeline.history

    @property
    def points(self) -> list[tuple[float, int, int]]:
        """(t, node, index) where an expected value may have changed (index -1: all)."""
        return self.timeline.points

    def known(self, node: int, index: int, subindex: int, t: float) -> Known | None:
        """The value an object is expected to hold at time t: the last one the log showed
        at or before t (a write or a read, unless the node was reset since), else the
        user's declaration, else the profile's (None: nothing says)."""
        entry = self.timeline.last(node, index, subindex, t)
        if entry is not None:
            return Known(entry[2].value, "log")
        return self.declared(node, index, subindex)

    def declared(self, node: int, index: int, subindex: int) -> Known | None:
        """The value before the log says anything (and after each reset of the node)."""
        value = self._file.get((node, index, subindex))
        if value is not None:
            return Known(value, "file")
        cfg = self.nodes.get(node)
        if cfg is not None and cfg.profile is not None:
            p = cfg.profile.value(index, subindex, node)
            if isinstance(p, int) and not isinstance(p, bool):
                return Known(p, "profile")
        return None

    def bus_known(self, index: int, t: float) -> Known | None:
        """A bus-wide object (SYNC 0x1006/0x1007): the latest value the log showed on any
        node, else the network's declaration ([sync]), else the SYNC producer's profile."""
        latest = self.timeline.latest(index, t)
        if latest is not None:
            return Known(latest.value, "log")
        value = self._bus_file.get((index, 0))
        if value is not None:
            return Known(value, "file")
        for node, cfg in sorted(self.nodes.items()):
            if cfg.sync_cob_raw is not None and cfg.sync_cob_raw & 0x40000000:
                return self.declared(node, index, 0)
        return None

    def subindices(self, node: int, index: int) -> list[int]:
        """Sub-indices 1.. of an array object (0x1016) that the user, the log or the
        node's profile gives a value for."""
        subs = {s for (n, i, s) in self._file if n == node and i == index and s}
        subs |= {s for s in self.timeline.subindices(node, index) if s}
        cfg = self.nodes.get(node)
        count = cfg.profile.value(index, 0, node) if cfg and cfg.profile else None
        if isinstance(count, int):
            subs |= set(range(1, min(count, 127) + 1))
        return sorted(subs)

    def binding_at(self, cob_id: int, t: float) -> PdoBinding | None:
        """The PDO a COB-ID carried at time t (the bindings after every change up to t)."""
        k = bisect.bisect_right(self.binding_times, t) - 1
        return self.binding_log[max(k, 0)].get(cob_id) if self.binding_log else None

    def srdo_at(self, cob_id: int, t: float) -> tuple[SrdoConfig, bool] | None:
        """The SRDO a COB-ID carried at time t, and whether as its inverted frame."""
        k = bisect.bisect_right(self.srdo_times, t) - 1
        return self.srdo_log[max(k, 0)].get(cob_id) if self.srdo_log else None

    def srdo_log_index(self, t: np.ndarray) -> np.ndarray:
        """Per time: the index in `srdo_log` of the SRDO bindings in force."""
        k = np.searchsorted(np.asarray(self.srdo_times, np.float64), t, side="right") - 1
        return np.maximum(k, 0)

    def binding(self, cob_id: int) -> PdoBinding | None:
        return self.bindings.get(cob_id)

    # --- Processor ---------------------------------------------------------------
    def may_identify(self, node: int, index: int, subindex: int) -> bool:
        """Whether reading this object of this node may name its device: an identity
        object whose value the model has not seen, on a node the user did not declare."""
        key = IDENTITY.get((index, subindex))
        cfg = self.nodes.get(node)
        if key is None or (cfg is not None and cfg.identified_by in USER_SOURCES):
            return False
        return cfg is None or key not in cfg.identity

    def identify_now(self, row: int, rec: dict) -> None:
        """An identity read as the SDO tracker ends it (before the later transfers of the
        batch are named): applied now, its changes taken up at its row by `process`."""
        self._early[id(rec)] = (rec, self._on_sdo(rec))

    def process(self, batch: DecodedBatch) -> None:
        self.segments = [(0, self.bindings)]
        early, self._early = self._early, {}
        events = [
            (row, rec)
            for row, rec in self._candidates(batch)
            if rec.get("kind") == "sdo" and rec.get("result") == "ok"
        ]
        events += self.resets_in(batch)
        events.sort(key=lambda e: e[0])
        n = len(batch)
        for row, rec in events:
            if isinstance(rec, tuple):
                changed = self._on_reset(*rec)
            elif id(rec) in early:
                changed = early[id(rec)][1]  # applied when the tracker ended it
            else:
                changed = self._on_sdo(rec)
            if changed is None:
                continue
            start = max(0, min(row + 1, n))
            if self.segments[-1][0] == start:
                self.segments[-1] = (start, self.bindings)
            else:
                self.segments.append((start, self.bindings))
            if changed and start < n:
                self._reclassify(batch, start, changed)
        self._seen_srdos(batch)

    def _seen_srdos(self, batch: DecodedBatch) -> None:
        """SRDOs nothing configured, known by their pattern: a frame on a node's default
        SRDO 1 COB-ID (0x0FF + 2 * node-ID) whose next frame on 0x101-0x180 is on the next
        COB-ID with the same length and every byte inverted (protocol/srdo.py). From the
        first frame of the batch on either COB-ID on, both are that SRDO's (and 0x001 the
        GFC): not unknown identifiers, and judged by the `srdo` rule (the inversion; its
        times are not known). Frames no COB-ID table names are the only ones looked at,
        and not on an identifier the network file or a DBC declares."""
        svc = batch.service
        other = np.flatnonzero(svc == Service.OTHER)
        if other.size < 2:
            return
        fb = batch.frames
        ids = fb.can_id[other]
        near = (ids >= srdo_layout.FIRST_COB) & (ids <= srdo_layout.LAST_COB)
        near &= (fb.flags[other] & (FLAG_EXT | FLAG_ERR | FLAG_RTR)) == 0
        if self.spec.known_cob_ids:  # the user's (or a DBC's) identifiers are not SRDOs
            declared = np.fromiter(self.spec.known_cob_ids, np.int64, len(self.spec.known_cob_ids))
            near &= ~np.isin(ids, declared)
        rows = other[near]
        if rows.size < 2:
            return
        ids = fb.can_id[rows].astype(np.int64)
        a, b = rows[:-1], rows[1:]
        dlc = fb.dlc[a]
        pair = (ids[:-1] % 2 == 1) & (ids[1:] == ids[:-1] + 1) & (fb.dlc[b] == dlc) & (dlc > 0)
        k = np.flatnonzero(pair)
        if k.size == 0:
            return
        k = k[~srdo_layout.not_inverted(fb.data[a[k], :8], fb.data[b[k], :8], dlc[k])]
        first = len(batch)
        for cob in np.unique(ids[:-1][k]).tolist():
            node = srdo_layout.default_owner(cob)
            if node is None or node in self._seen_srdo:
                continue
            self._seen_srdo.add(node)
            if self._adopt_seen_srdo(self.config_at(node)):
                first = min(first, int(rows[np.flatnonzero((ids == cob) | (ids == cob + 1))[0]]))
        if first == len(batch):
            return
        t = float(fb.t[first])
        self._rebind(max(t, self.srdo_times[-1]) if self.srdo_times else t)
        changed = self._sync_classifier()
        if changed:
            self._reclassify(batch, first, changed)

    def finish(self, batch: DecodedBatch) -> None:
        self.segments = [(0, self.bindings)]

    def _candidates(self, batch: DecodedBatch) -> list:
        """The records `_on_sdo` may act on, in record order; the fast path's others skipped.

        A fast-path record (expedited, with data) matters only when it writes or reads
        a communication object (0x1000-0x1FFF) or a unit-changing object, or is the
        first seen of a node the model does not know yet: `_on_sdo` leaves the state
        untouched for every other one. A batch with an identity read takes them all.
        """
        recs = batch.records
        c = recs.cols
        if (c.upload & np.isin(c.index, _IDENTITY_INDICES)).any():
            return list(recs)
        want = (c.req_row < 0) | (c.ok & (c.index >= 0x1000) & (c.index <= 0x1FFF))
        context = {o for cfg in self.nodes.values() for o in cfg.context_objects()}
        if context:
            key = c.index * 256 + c.subindex
            objs = np.array([i * 256 + s for i, s in context], np.int64)
            want |= c.ok & np.isin(key, objs)
        known = np.array(sorted(self.nodes), np.int64)
        new = c.ok & ~np.isin(c.node, known)
        if new.any():
            _, first = np.unique(c.node[new], return_index=True)
            want[np.flatnonzero(new)[first]] = True
        return recs.picked(np.flatnonzero(want).tolist())

    # --- internals ---------------------------------------------------------------
    def _on_sdo(self, rec: dict) -> set[int] | None:
        """Apply one completed transfer; None if nothing that decoding depends on changed,
        else the COB-IDs whose classification changed (maybe empty)."""
        node, index, sub = rec.get("node"), rec.get("index"), rec.get("subindex")
        if not isinstance(node, int) or index is None or sub is None:
            return None
        upload = rec.get("direction") == "upload"
        value = sdo_value(rec)
        if value is None:
            return None
        t = float(rec.get("t") or 0.0)
        if upload and (index, sub) in IDENTITY:
            cfg = self.config_at(node)
            cfg.identity[IDENTITY[(index, sub)]] = value
            return self._identify(cfg, t)
        known = self.nodes.get(node)
        tracked = 0x1000 <= index <= 0x1FFF or (
            known is not None and (index, sub) in known.context_objects()
        )
        cfg = self.config_at(node)  # a node that answers SDO exists
        if not tracked or isinstance(value, str):
            return None  # most SDO traffic: process data, names
        before = self.known(node, index, sub, t)
        change = ConfigChange(t, node, (index, sub), value, "read" if upload else "write")
        same = before is not None and before.value == value
        self.timeline.add(change, changed=not same)
        if same:
            return None  # a read-back (or write) of the value in force: nothing changes
        if cfg.apply(index, sub, value) not in TOUCHES_COB_IDS:
            return None
        self._rebind(t)
        return self._sync_classifier()

    def resets_in(self, batch: DecodedBatch) -> list[tuple[int, tuple[float, int, str]]]:
        """Boot-ups and NMT reset commands of a batch: (row, (t, node, kind))."""
        svc = batch.service
        rows = np.flatnonzero((svc == Service.BOOTUP) | (svc == Service.NMT))
        if rows.size == 0:
            return []
        fb = batch.frames
        out = []
        for row in rows.tolist():
            t = float(fb.t[row])
            if svc[row] == Service.BOOTUP:
                out.append((row, (t, int(batch.node[row]), "boot-up")))
            elif fb.dlc[row] >= 2 and fb.data[row, 0] in (0x81, 0x82):
                kind = "reset node" if fb.data[row, 0] == 0x81 else "reset communication"
                out.append((row, (t, int(fb.data[row, 1]), kind)))
        return out

    def _on_reset(self, t: float, node: int, kind: str) -> set[int] | None:
        """A node (0: every node) back to its declared values."""
        if not node:
            self.timeline.reset_all(t)
        targets = [node] if node else sorted(set(self.nodes) | self.timeline.nodes())
        rebuilt = False
        for n in targets:
            cfg = self.nodes.get(n)
            if not self.timeline.reset(t, n, kind) or cfg is None:
                continue
            fresh = self._declared_config(n, cfg.profile, cfg.identified_by)
            fresh.identity = cfg.identity
            for c in self.timeline.since_reset(n):  # a reset communication keeps these
                fresh.apply(*c.object, c.value)
            self.nodes[n] = fresh
            rebuilt = True
        if not rebuilt:
            return None
        self._rebind(t)
        return self._sync_classifier()

    def _identify(self, cfg: NodeConfig, t: float) -> set[int] | None:
        if cfg.identified_by in USER_SOURCES:
            return None
        ident = cfg.identity
        prof = identify(
            ident.get("vendor_id"),
            ident.get("product_code"),
            ident.get("device_type"),
            ident.get("device_name"),
        )
        if prof is None and cfg.profile is None:
            # no device of ours, but a device type naming CiA 402/401: the profile's defaults
            prof = generic_for(ident.get("device_type"))
        if prof is None or (cfg.profile is not None and cfg.profile.key == prof.key):
            return None
        how = (
            "SDO 0x1000 device type"
            if prof.generic
            else "SDO 0x1018 vendor/product"
            if "vendor_id" in ident or "product_code" in ident
            else "SDO 0x1008 name"
        )
        fresh = self._declared_config(cfg.node, prof, how)
        fresh.identity = dict(cfg.identity)
        fresh.sdo_channels = cfg.sdo_channels
        for change in self.timeline.since_reset(cfg.node):  # what the log changed still holds
            fresh.apply(*change.object, change.value)
        self.nodes[cfg.node] = fresh
        self.timeline.mark(t, cfg.node)
        self._info.clear()
        self._rebind(t)
        return self._sync_classifier()

    def _rebind(self, t: float) -> None:
        valid: dict[int, PdoBinding] = {}
        fallback: dict[int, PdoBinding] = {}
        for node, cfg in sorted(self.nodes.items()):
            for (direction, number), state in sorted(cfg.pdos.items()):
                cob, ok = split_cob_id(state.cob_raw)
                if not cob:
                    continue
                kind = "tpdo" if direction == "tx" else "rpdo"
                if ok:
                    valid.setdefault(cob, PdoBinding(node, kind, number, cfg.pdo_config(state)))
                else:
                    fallback.setdefault(
                        cob,
                        PdoBinding(
                            node,
                            kind,
                            number,
                            cfg.pdo_config(state),
                            f"{kind.upper()}{number} of node {node} {NOT_VALID}",
                        ),
                    )
        for cob, b in fallback.items():
            valid.setdefault(cob, b)
        if valid != self.bindings or not self.binding_log:
            self.bindings = valid
            self.binding_times.append(t)
            self.binding_log.append(valid)
        self._rebind_srdo(t)

    def _rebind_srdo(self, t: float) -> None:
        """The SRDOs in force: each in-use SRDO's two COB-IDs, the producer's parameters
        first (a consumer's, with the same COB-IDs, only where no producer's are known)."""
        found: dict[int, tuple[SrdoConfig, bool]] = {}
        configs = [
            c
            for node, cfg in sorted(self.nodes.items())
            for _, state in sorted(cfg.srdos.items())
            if (c := cfg.srdo_config(state)) is not None
        ]
        configs.sort(key=lambda c: c.direction != 1)  # producers first, stable
        for c in configs:
            found.setdefault(c.cob_normal, (c, False))
            found.setdefault(c.cob_inverted, (c, True))
        if found != self.srdo_bindings or not self.srdo_log:
            self.srdo_bindings = found
            self.srdo_times.append(t)
            self.srdo_log.append(found)

    def _wanted(self) -> dict[int, tuple[int, int, int]]:
        out: dict[int, tuple[int, int, int]] = {}
        for node, cfg in self.nodes.items():
            if cfg.sync_cob_raw is not None:
                out[cfg.sync_cob_raw & 0x7FF] = (Service.SYNC, NO_NODE, 0)
            if cfg.emcy_cob_raw is not None:
                cob, ok = split_cob_id(cfg.emcy_cob_raw)
                if ok and cob:
                    out[cob] = (Service.EMCY, node, 0)
        for cob, b in self.bindings.items():
            if b.problem is None:
                out[cob] = (Service.TPDO if b.kind == "tpdo" else Service.RPDO, b.node, b.number)
        for cob, (c, inverted) in self.srdo_bindings.items():
            out[cob] = (Service.SRDO_INVERTED if inverted else Service.SRDO, c.node, c.number)
        if self.srdo_bindings:  # a safety bus: 0x001 is its global fail-safe command
            out[srdo_layout.GFC_COB_ID] = (Service.GFC, NO_NODE, 0)
        return out

    def _sync_classifier(self) -> set[int]:
        """Edit the classifier tables to match; return the COB-IDs whose meaning changed."""
        if self.classifier is None:
            return set()
        wanted = self._wanted()
        changed: set[int] = set()
        for cob in set(self._assigned) - set(wanted):
            self.classifier.release(cob)
            changed.add(cob)
        for cob, entry in wanted.items():
            if self._assigned.get(cob) != entry:
                self.classifier.assign(cob, *entry)
                changed.add(cob)
        self._assigned = wanted
        return {c for c in changed if 0 <= c < 2048}

    def _reclassify(self, batch: DecodedBatch, start: int, cobs: set[int]) -> None:
        fb = batch.frames
        ids = fb.can_id[start:]
        std = (fb.flags[start:] & (FLAG_EXT | FLAG_ERR)) == 0
        rows = np.flatnonzero(std & np.isin(ids, np.fromiter(cobs, np.uint32))) + start
        if rows.size == 0 or self.classifier is None:
            return
        idx = fb.can_id[rows].astype(np.intp)
        batch.service[rows] = self.classifier.svc[idx]
        batch.node[rows] = self.classifier.node[idx]
        batch.pdo[rows] = self.classifier.pdo[idx]
