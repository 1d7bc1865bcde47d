"""NetworkModel: the analyser's picture of each node, kept up to date from the log.

It starts from what the user declared (profiles, network file) and then follows
completed SDO transfers in time order: downloads change PDO, heartbeat, guarding,
SYNC and EMCY parameters and unit-changing device objects; uploads of the identity
objects (0x1018, 0x1000, 0x1008) pick a built-in profile. It keeps the COB-ID
classifier's tables in step, so a PDO moved to another COB-ID is attributed to the
right node from the frame after the write on, re-classifying the rest of the batch.
Per-frame Python here touches only SDO records, which are rare.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..frames import FLAG_ERR, FLAG_EXT
from ..protocol.cobid import NO_NODE, CobClassifier
from ..protocol.comm_objects import comm_object
from ..protocol.services import Service
from ..records import DecodedBatch
from .node_config import TOUCHES_COB_IDS, NodeConfig
from .node_tally import IDENTITY
from .pdo_map import PdoConfig, split_cob_id
from .profile import identify
from .spec import NetworkSpec

if TYPE_CHECKING:
    from ..pipeline import Decoder

NOT_VALID = (
    "is not valid (COB-ID bit 31 set)"  # PdoBinding.problem; the pdo_not_valid rule looks for it
)
_IDENTITY_INDICES = np.array([0x1018, 0x1000, 0x1008], np.int64)
USER_SOURCES = ("user --device", "user --eds", "network file")


@dataclass(frozen=True)
class PdoBinding:
    """Which node's PDO a COB-ID carries, with the mapping in force."""

    node: int
    kind: str  # "tpdo" / "rpdo"
    number: int
    config: PdoConfig
    problem: str | None = None  # set when frames arrive on a PDO that is not valid


@dataclass(frozen=True)
class ConfigChange:
    t: float
    node: int
    object: tuple[int, int]  # (index, subindex)
    value: int


def _sdo_value(rec: dict) -> int | str | None:
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
        self.history: list[ConfigChange] = []
        # the same changes by object: value_at is asked per node and batch by the checks
        self._changes: dict[tuple[int, int, int], list[ConfigChange]] = {}
        self._objects: set[tuple[int, int]] = set()
        self.bindings: dict[int, PdoBinding] = {}
        # Bindings in force within the current batch: (first row, bindings), ascending.
        self.segments: list[tuple[int, dict[int, PdoBinding]]] = [(0, {})]
        self.classifier: CobClassifier | None = None
        self._assigned: dict[int, tuple[int, int, int]] = {}
        # (node, index, subindex) -> object_info answer; cleared when a node's profile changes
        self._info: dict[tuple[int, int, int], tuple[str, int] | None] = {}
        for node, ns in self.spec.nodes.items():
            cfg = NodeConfig.from_profile(node, ns.profile, ns.how)
            for index, sub, value in ns.writes:
                cfg.apply(index, sub, value)
            cfg.sdo_channels = list(ns.sdo_channels)
            self.nodes[node] = cfg
        self._rebind()
        if classifier is not None:
            self.bind(classifier)

    # --- wiring ------------------------------------------------------------------
    def bind(self, classifier: CobClassifier) -> None:
        """Give the model the decoder's classifier (before the first batch is decoded)."""
        self.classifier = classifier
        self._assigned = {}
        self._sync_classifier()

    def attach(self, decoder: Decoder) -> NetworkModel:
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

    def config_at(self, node: int) -> NodeConfig:
        """Current configuration of a node (an empty 'unknown' one if never seen)."""
        cfg = self.nodes.get(node)
        if cfg is None:
            cfg = self.nodes[node] = NodeConfig(node)
            self._info.clear()
        return cfg

    def value_at(self, node: int, index: int, subindex: int, t: float) -> int | None:
        """Last value written to an object at or before time t (None: never written in the log)."""
        for change in reversed(self._changes.get((node, index, subindex), ())):
            if change.t <= t:
                return change.value
        return None

    def written(self, node: int, index: int) -> bool:
        """Whether the log wrote any sub-index of this object on this node (so far)."""
        return (node, index) in self._objects

    def binding(self, cob_id: int) -> PdoBinding | None:
        return self.bindings.get(cob_id)

    # --- Processor ---------------------------------------------------------------
    def process(self, batch: DecodedBatch) -> None:
        self.segments = [(0, self.bindings)]
        events = [
            (row, rec)
            for row, rec in self._candidates(batch)
            if rec.get("kind") == "sdo" and rec.get("result") == "ok"
        ]
        events.sort(key=lambda e: e[0])
        n = len(batch)
        for row, rec in events:
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

    def finish(self, batch: DecodedBatch) -> None:
        self.segments = [(0, self.bindings)]

    def _candidates(self, batch: DecodedBatch) -> list:
        """The records `_on_sdo` may act on, in record order; the fast path's others skipped.

        A fast-path record (expedited, with data) matters only when it writes a
        communication object (0x1000-0x1FFF) or a unit-changing object, or is the
        first seen of a node the model does not know yet: `_on_sdo` leaves the state
        untouched for every other one. A batch with an identity read takes them all.
        """
        records = batch.records
        fast = batch.sdo_fast
        if fast is None or fast.slots.size == 0 or len(records) <= int(fast.slots[-1]):
            return records
        rest = np.ones(len(records), bool)
        rest[fast.slots] = False
        others = np.flatnonzero(rest).tolist()
        # an identification may bring a profile with other unit-changing objects: all then
        get = list.__getitem__  # the other records are written: no lazy lookup for them
        if (fast.upload & np.isin(fast.index, _IDENTITY_INDICES)).any() or any(
            rec.get("direction") == "upload" and (rec.get("index"), rec.get("subindex")) in IDENTITY
            for _, rec in (get(records, k) for k in others)
        ):
            return records
        want = fast.ok & ~fast.upload & (fast.index >= 0x1000) & (fast.index <= 0x1FFF)
        context = {o for cfg in self.nodes.values() for o in cfg.context_objects()}
        if context:
            key = fast.index * 256 + fast.subindex
            objs = np.array([i * 256 + s for i, s in context], np.int64)
            want |= fast.ok & ~fast.upload & np.isin(key, objs)
        known = np.array(sorted(self.nodes), np.int64)
        new = fast.ok & ~np.isin(fast.node, known)
        if new.any():
            _, first = np.unique(fast.node[new], return_index=True)
            want[np.flatnonzero(new)[first]] = True
        picked = [(k, get(records, k)) for k in others]
        picked += [(k, records[k]) for k in fast.slots[want].tolist()]  # built one by one
        if len(picked) > len(others):
            picked.sort(key=lambda x: x[0])
        return [rec for _, rec in picked]

    # --- internals ---------------------------------------------------------------
    def _on_sdo(self, rec: dict) -> set[int] | None:
        """Apply one completed transfer; None if nothing that decoding depends on changed,
        else the COB-IDs whose classification changed (maybe empty)."""
        node, index, sub = rec.get("node"), rec.get("index"), rec.get("subindex")
        if not isinstance(node, int) or index is None or sub is None:
            return None
        upload = rec.get("direction") == "upload"
        if upload and (index, sub) not in IDENTITY:
            # a poll of some other object (most SDO traffic): only the node becomes known
            if node not in self.nodes and _sdo_value(rec) is not None:
                self.config_at(node)
            return None
        value = _sdo_value(rec)
        if value is None:
            return None
        t = float(rec.get("t") or 0.0)
        cfg = self.config_at(node)
        if upload:
            cfg.identity[IDENTITY[(index, sub)]] = value
            return self._identify(cfg)
        if isinstance(value, str):
            return None
        what = cfg.apply(index, sub, value)
        if what is None:
            return None
        change = ConfigChange(t, node, (index, sub), value)
        self.history.append(change)
        self._changes.setdefault((node, index, sub), []).append(change)
        self._objects.add((node, index))
        if what not in TOUCHES_COB_IDS:
            return None
        self._rebind()
        return self._sync_classifier()

    def _identify(self, cfg: NodeConfig) -> set[int] | None:
        if cfg.identified_by in USER_SOURCES:
            return None
        ident = cfg.identity
        prof = identify(
            ident.get("vendor_id"),
            ident.get("product_code"),
            ident.get("device_type"),
            ident.get("device_name"),
        )
        if prof is None or (cfg.profile is not None and cfg.profile.key == prof.key):
            return None
        how = (
            "SDO 0x1018 vendor/product"
            if "vendor_id" in ident or "product_code" in ident
            else "SDO 0x1008 name"
        )
        fresh = NodeConfig.from_profile(cfg.node, prof, how)
        fresh.identity = dict(cfg.identity)
        fresh.sdo_channels = cfg.sdo_channels
        for change in self.history:  # what the log already changed still holds
            if change.node == cfg.node:
                fresh.apply(*change.object, change.value)
        self.nodes[cfg.node] = fresh
        self._info.clear()
        self._rebind()
        return self._sync_classifier()

    def _rebind(self) -> None:
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
        self.bindings = valid

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
