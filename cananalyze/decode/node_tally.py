"""What the nodes table says of each node, gathered batch by batch.

Frames per service, the last NMT state reported, the identity objects the
node answered to SDO uploads (0x1000, 0x1008, 0x1018), matched to a device
profile when none was given, and the nominal bits of the frames it sent itself
with its share of the bus (node_load: the figures `decode --summary` prints). The Capture tallies a whole log at once; the
streaming exports (Parquet/CSV tables, MCAP's nodes.json) one batch at a time,
so memory does not grow with the log.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from cananalyze.core.frames import MAX_BUSES, MAX_CHANNELS, OTHER_CHANNELS
from cananalyze.core.records import DecodedBatch, sender_counts
from cananalyze.decode.node_load import NodeLoad
from cananalyze.protocol.services import SERVICE_NAMES

IDENTITY = {
    (0x1000, 0): "device_type",
    (0x1018, 1): "vendor_id",
    (0x1018, 2): "product_code",
    (0x1018, 3): "revision",
    (0x1018, 4): "serial",
    (0x1008, 0): "device_name",
}
IDENTITY_INDEX = (0x1000, 0x1008, 0x1018)
IDENTITY_KEYS = ("device_type", "vendor_id", "product_code", "revision", "serial", "device_name")


class NodeTally:
    """Per-node counts, last state and identity; `rows()` gives the nodes table.

    Several buses (frames of more than one channel): node 5 on can0 and node 5 on can1
    are two rows, each with a `bus` column (a log of one bus has no such column)."""

    def __init__(self) -> None:
        self.counts = np.zeros((128, len(SERVICE_NAMES)), np.int64)
        self.last_state: dict[int, tuple[float, str]] = {}
        self.identity: dict[int, dict] = {}
        # several buses: channel name -> a tally of its own (None: one bus so far)
        self.buses: dict[str, NodeTally] | None = None
        self._channel: int | None = None  # the one channel seen so far
        self._names: tuple[str, ...] = ()
        self.load = NodeLoad()  # bits each node sent, per bus (the top tally's only)

    def add(self, batch: DecodedBatch, states: Iterable, offset: int | None = None) -> None:
        """One decoded batch and its NMT state changes (`Row`s or `Event`s); `offset`: the
        row number of the batch's first frame in the states' rows (several buses)."""
        fb = batch.frames
        self.load.add(batch)
        if self.buses is None and len(fb):
            if self._channel is None:
                self._channel, self._names = int(fb.channel[0]), fb.channels
            if (fb.channel != self._channel).any():
                self._split(fb.channel_label(self._channel))
        if self.buses is not None:
            self._add_buses(batch, list(states), offset)
            return
        # the batch's count, shared with the boot-up rule
        self._add_counts(batch.sender_counts(), batch.service, batch.node)
        self.add_states(states)
        self.add_identity(identity_records(batch))

    def _split(self, first: str) -> None:
        """A second bus: what was tallied so far is the first bus's."""
        mine = NodeTally()
        mine.counts, mine.last_state, mine.identity = self.counts, self.last_state, self.identity
        self.counts = np.zeros_like(self.counts)
        self.last_state, self.identity = {}, {}
        self.buses = {first: mine}
        self._lut = np.full(MAX_CHANNELS, -1, np.int32)  # channel -> index in buses

    def _add_buses(self, batch: DecodedBatch, states: list, offset: int | None) -> None:
        fb = batch.frames
        n = len(fb)
        off = 0 if offset is None else offset  # the states' row of the batch's first frame
        # each row's tally: its bus's, or past MAX_BUSES the one the others share
        lut = self._lut
        for c in np.flatnonzero(np.bincount(fb.channel, minlength=1)).tolist():
            if lut[c] < 0:
                name = fb.channel_label(c)
                if name not in self.buses and len(self.buses) >= MAX_BUSES - 1:
                    name = OTHER_CHANNELS
                self.buses.setdefault(name, NodeTally())
                lut[c] = list(self.buses).index(name)
        tallies = list(self.buses.values())
        slot = lut[fb.channel]
        order = np.argsort(slot, kind="stable")
        for rows in np.split(order, np.flatnonzero(np.diff(slot[order])) + 1):
            if rows.size:
                tallies[int(slot[rows[0]])].add_frames(batch.service[rows], batch.node[rows])
        by: dict[int, list] = {}
        for ev in states:
            if ev.row is not None and 0 <= ev.row - off < n:
                by.setdefault(int(slot[ev.row - off]), []).append(ev)
        for k, evs in by.items():
            tallies[k].add_states(evs)
        recs: dict[int, list] = {}
        for k, r in identity_records(batch):
            row = batch.records[k][0]
            if 0 <= row < n:
                recs.setdefault(int(slot[row]), []).append((k, r))
        for k, rs in recs.items():
            tallies[k].add_identity(rs)

    def add_frames(self, service: np.ndarray, node: np.ndarray) -> None:
        """Count frames per (node, service) (`records.sender_counts`)."""
        self._add_counts(sender_counts(service, node), service, node)

    def _add_counts(self, counts: np.ndarray | None, service: np.ndarray, node: np.ndarray) -> None:
        if counts is None:  # a node outside -1..127 (not a node-ID): its rows not counted
            keep = (node >= -1) & (node <= 127)
            counts = sender_counts(service[keep], node[keep])
        self.counts += counts[: len(SERVICE_NAMES), 1:].T

    def add_states(self, states: Iterable) -> None:
        """The latest state by time wins; of equal times, the later one."""
        for ev in states:
            cur = self.last_state.get(ev.node)
            if cur is None or ev.t >= cur[0]:
                self.last_state[ev.node] = (ev.t, ev.message)

    def add_identity(self, records: list[tuple[int, dict]]) -> None:
        for node, info in identity(records).items():
            self.identity.setdefault(node, {}).update(info)

    def rows(
        self,
        profiles: dict[int, tuple[str, str]],
        by_bus: dict[str, dict[int, tuple[str, str]]] | None = None,
        bitrate: int | None = None,
    ) -> list[dict]:
        """One dict per node seen: frames, frames_<service> for every service seen,
        last_state(_t), identity, profile and how it was identified, the bits it sent and
        its share of the bus at `bitrate` (None without one or without times); with
        several buses, one per bus and node, `bus` first, each bus's profiles from
        `by_bus` (its own network model) where given."""
        rows = self._rows(profiles, by_bus)
        sent, shares = self.load.sent, self.load.shares(bitrate)
        one = next(iter(sent)) if len(sent) == 1 else None
        for row in rows:
            bus = row.get("bus", one)
            got = sent.get(bus)
            row["bits"] = int(got[1][row["node"]]) if got is not None else 0
            row["bus_load_percent"] = shares.get(bus, {}).get(row["node"])
        return rows

    def _rows(self, profiles: dict, by_bus: dict | None) -> list[dict]:
        if self.buses is not None:
            by_bus = by_bus or {}
            parts = [
                (name, t._rows(by_bus.get(name, profiles), None)) for name, t in self.buses.items()
            ]
            seen = [k for _, rows in parts for r in rows for k in r]
            services = [k for k in dict.fromkeys(seen) if k.startswith("frames_")]
            out = []
            for name, rows in parts:
                for r in rows:
                    row = {"bus": name, "node": r["node"], "frames": r["frames"]}
                    row.update({k: r.get(k, 0) for k in services})
                    row.update({k: v for k, v in r.items() if k not in row})
                    out.append(row)
            return out
        counts = self.counts
        seen = np.flatnonzero(counts.sum(axis=0)).tolist()
        rows: list[dict] = []
        for n in np.flatnonzero(counts.sum(axis=1)).tolist():
            row: dict[str, Any] = {"node": n, "frames": int(counts[n].sum())}
            for s in seen:
                row[f"frames_{SERVICE_NAMES[s]}"] = int(counts[n, s])
            row["last_state"] = self.last_state.get(n, (None, None))[1]
            row["last_state_t"] = self.last_state.get(n, (None, None))[0]
            info = self.identity.get(n, {})
            row.update({k: info.get(k) for k in IDENTITY_KEYS})
            prof, how = profiles.get(n, (None, None))
            if prof is None and info:
                prof, how = match_profile(info)
            row["profile"] = prof
            row["identified_by"] = how
            rows.append(row)
        return rows


def bus_profiles(decoder) -> dict[str, dict[int, tuple[str, str]]]:
    """bus -> `node_profiles` of that bus's network model (`Decoder.networks`; empty on a
    log of one bus): the nodes table's profile column per bus."""
    if decoder is None:
        return {}
    return {b: node_profiles(m) for b, m in decoder.networks().items() if b is not None}


def node_profiles(model) -> dict[int, tuple[str, str]]:
    """node -> (profile, how it was found) of every node the network model has a device for:
    declared (--device, --eds, the network file) or identified from the log."""
    out: dict[int, tuple[str, str]] = {}
    for node, cfg in sorted(getattr(model, "nodes", {}).items()):
        if cfg.profile is not None:
            out[node] = (cfg.profile.key, cfg.identified_by)
    return out


def identity_records(batch: DecodedBatch) -> list[tuple[int, dict]]:
    """(record position, record) of the batch's SDO records on identity objects, in order;
    only those are built as dicts."""
    recs = batch.records
    at = np.flatnonzero(np.isin(recs.cols.index, IDENTITY_INDEX)).tolist() if recs else []
    return [(k, recs.record(k)) for k in at]


def identity(records: Iterable[tuple[int, dict]]) -> dict[int, dict]:
    """Identity objects a node answered to SDO uploads, the last answer winning."""
    out: dict[int, dict] = {}
    for _, r in records:
        if r.get("kind") != "sdo" or r.get("result") != "ok" or r.get("direction") != "upload":
            continue
        what = IDENTITY.get((r.get("index"), r.get("subindex")))
        if what and r.get("node") is not None:
            value = r.get("value")
            if value is None and r.get("data"):  # no dictionary known: the CiA 301 types
                raw = bytes.fromhex(r["data"])
                if what == "device_name":
                    value = raw.split(b"\0", 1)[0].decode("latin-1")
                else:
                    value = int.from_bytes(raw[:4], "little")
            out.setdefault(r["node"], {})[what] = value
    return out


def match_profile(info: dict) -> tuple[str | None, str | None]:
    """The built-in profile the identity names, and "sdo identity"; (None, None) if none."""
    try:
        from cananalyze.devices.builtin import identify

        ints = {
            k: info.get(k) if isinstance(info.get(k), int) else None
            for k in ("vendor_id", "product_code", "device_type")
        }
        name = info.get("device_name")
        prof = identify(device_name=name if isinstance(name, str) else None, **ints)
    except (
        Exception
    ):  # identification is a nicety: a profile that fails to load must not stop a table
        return None, None
    return (prof.key, "sdo identity") if prof else (None, None)
