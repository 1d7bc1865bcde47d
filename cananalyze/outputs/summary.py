"""`decode --summary`: frames per service and node, duration, bus load. Columnar counts.

Bus load is a lower bound (nominal bits, no stuff bits): see cananalyze.busload.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import TextIO

import numpy as np

from cananalyze.checks.streamstats import StreamStats
from cananalyze.core.columns.order import first_seen_codes
from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_RTR
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.lss import identity_text
from cananalyze.decode.node_load import NodeLoad, run_bitrate
from cananalyze.pipeline.sink import Sink
from cananalyze.protocol import lss, nmt
from cananalyze.protocol.busload import bits_per_channel
from cananalyze.protocol.services import SERVICE_NAMES, Service

N_SVC = len(SERVICE_NAMES)
# byte -> is an NMT state (toggle bit ignored) / an NMT command: lookups, not np.isin per batch
_IS_STATE = np.isin(np.arange(256) & nmt.STATE_MASK, list(nmt.STATES))
_IS_COMMAND = np.isin(np.arange(256), list(nmt.COMMANDS))
_IS_LSS = np.isin(np.arange(256), list(lss.COMMANDS))


def _ids(per_id: np.ndarray, most: int = 6) -> str:
    """The identifiers with counts, most frequent first: '0x5CB, 0x64B'."""
    ids = np.flatnonzero(per_id)
    ids = ids[np.argsort(-per_id[ids], kind="stable")]
    text = ", ".join(f"0x{int(i):03X}" for i in ids[:most])
    return text + (f" and {ids.size - most} more" if ids.size > most else "")


@dataclass
class Summary:
    frames: int = 0
    t_first: float | None = None
    t_last: float | None = None
    by_service: np.ndarray = field(default_factory=lambda: np.zeros(N_SVC, np.int64))
    by_node_service: np.ndarray = field(default_factory=lambda: np.zeros((128, N_SVC), np.int64))
    bits: int = 0
    ids_seen: set = field(default_factory=set)
    skipped: int = 0
    # SDO transactions per node: result counts and latency statistics (not the records
    # nor every latency: a 50M-frame log has millions, and memory must stay flat)
    sdo_results: dict = field(default_factory=dict)  # node -> {result: count}
    sdo_latency: dict = field(default_factory=dict)  # node -> StreamStats of ms
    # evidence for and against CANopen (canopen_verdict), counted as columns
    ext_frames: int = 0  # 29-bit identifiers
    sdo_frames: int = 0  # data frames in the SDO ranges
    sdo_bad: np.ndarray = field(
        default_factory=lambda: np.zeros(2048, np.int64)
    )  # not 8 bytes, per id
    ec_frames: int = 0  # data frames in the heartbeat range
    ec_bad: np.ndarray = field(
        default_factory=lambda: np.zeros(2048, np.int64)
    )  # not 1 byte NMT state
    nmt_good: int = 0  # well-formed NMT commands
    by_channel: dict = field(default_factory=dict)  # channel name -> [frames, bits]
    nodes_by_channel: dict = field(default_factory=dict)  # channel name -> nodes seen on it
    # a log of several buses: node 5 on can0 and node 5 on can1 are two devices, so the
    # frames and SDO transactions per node are kept per bus too (the decoder's bus names;
    # what was counted before a second bus was seen is the first bus's). Empty on one
    # bus, where they would only repeat by_node_service and sdo_results.
    first_bus: str | None = None  # the first frame's
    node_service_by_bus: dict = field(default_factory=dict)  # bus -> (128, N_SVC) counts
    sdo_results_by_bus: dict = field(default_factory=dict)  # (bus, node) -> {result: count}
    sdo_latency_by_bus: dict = field(default_factory=dict)  # (bus, node) -> StreamStats
    # CiA 305 steps and assignments, as the decoder's one follower made them
    # (decode/commissioning: `DecodedBatch.commissioning`)
    lss_assignments: list = field(default_factory=list)
    lss_steps: int = 0
    lss_good: int = 0  # LSS master frames with a known command: CANopen evidence
    # bus load per node and the longest burst per channel (node_load; its `bitrate` set
    # before the first batch: a frame's time on the wire depends on it)
    load: NodeLoad = field(default_factory=NodeLoad)

    def add(self, batch: DecodedBatch) -> None:
        n = len(batch)
        if self.first_bus is None and n:
            self.first_bus = batch.frames.channel_label(int(batch.frames.channel[0]))
        if batch.several and not self.node_service_by_bus:
            self._several()
        if batch.records:
            self._sdo(batch)
        for c in batch.commissioning:
            if c.kind == "lss":
                self.lss_steps += 1
                if c.assignment is not None:
                    self.lss_assignments.append(c.assignment)
        if n == 0:
            self.load.add(batch)  # the decoder's longest burst, on the log's last batch
            return
        fb = batch.frames
        self.frames += n
        t = fb.t
        self.t_first = float(t[0]) if self.t_first is None else min(self.t_first, float(t[0]))
        self.t_last = float(t[-1]) if self.t_last is None else max(self.t_last, float(t[-1]))
        self.by_service += np.bincount(batch.service, minlength=N_SVC)
        # node -1 (none) lands in the first N_SVC bins, dropped: no mask, no gather
        key = (batch.node.astype(np.intp) + 1) * N_SVC + batch.service
        per = np.bincount(key, minlength=129 * N_SVC)
        if per.size != 129 * N_SVC:  # a node outside -1..127: the rows with a node only
            has = batch.node >= 0
            key = batch.node[has].astype(np.int64) * N_SVC + batch.service[has]
            per = np.r_[np.zeros(N_SVC, np.int64), np.bincount(key, minlength=128 * N_SVC)]
        self.by_node_service += per[N_SVC:].reshape(128, N_SVC)
        if batch.several:
            self._by_bus(batch, per[N_SVC:].reshape(128, N_SVC))
        per_frames, per_bits = bits_per_channel(fb.flags, fb.dlc, fb.channel)
        self.bits += int(per_bits.sum())
        present = np.flatnonzero(per_frames).tolist()
        for c in present:
            entry = self.by_channel.setdefault(fb.channel_label(c), [0, 0])
            entry[0] += int(per_frames[c])
            entry[1] += int(per_bits[c])
        self._nodes_by_channel(batch, present, per[N_SVC:].reshape(128, N_SVC))
        self.load.add(batch, present)
        self._evidence(batch)
        if len(self.ids_seen) < 4096:
            ids = fb.can_id[(fb.flags & FLAG_EXT) == 0]
            if ids.size and ids.max() < 2048:  # 11-bit: a bincount, no sort
                ids = np.flatnonzero(np.bincount(ids, minlength=2048))
            else:
                ids = np.unique(ids)
            self.ids_seen.update(ids.tolist())

    def _several(self) -> None:
        """A second bus, before its batch is counted: what was counted so far is the
        first bus's."""
        first = self.first_bus
        self.node_service_by_bus[first] = self.by_node_service.copy()
        self.sdo_results_by_bus.update({(first, nd): dict(r) for nd, r in self.sdo_results.items()})
        self.sdo_latency_by_bus.update(
            {(first, nd): copy.deepcopy(st) for nd, st in self.sdo_latency.items()}
        )

    def _by_bus(self, batch: DecodedBatch, per: np.ndarray) -> None:
        """Frames per node and service of each bus of a batch of a log of several."""
        if batch.channel_bus is None:  # one bus's decoder made the whole batch
            self._add_bus(batch.bus or self.first_bus, per)
            return
        fb = batch.frames
        for c in np.flatnonzero(np.bincount(fb.channel, minlength=1)).tolist():
            at = (fb.channel == c) & (batch.node >= 0) & (batch.node < 128)
            key = batch.node[at].astype(np.intp) * N_SVC + batch.service[at]
            counts = np.bincount(key, minlength=128 * N_SVC).reshape(128, N_SVC)
            self._add_bus(batch.channel_bus[c] or self.first_bus, counts)

    def _add_bus(self, bus: str | None, counts: np.ndarray) -> None:
        have = self.node_service_by_bus.get(bus)
        if have is None:
            self.node_service_by_bus[bus] = counts.copy()
        else:
            have += counts

    def _nodes_by_channel(self, batch: DecodedBatch, present: list[int], per: np.ndarray) -> None:
        """The nodes seen on each channel (each bus's devices): this batch's node counts
        when it holds one channel, else a count per channel."""
        fb = batch.frames
        if len(present) == 1:
            seen = {present[0]: np.flatnonzero(per.sum(axis=1))}
        else:
            seen = {}
            for c in present:
                nodes = batch.node[(fb.channel == c) & (batch.node >= 0)]
                seen[c] = np.flatnonzero(np.bincount(nodes, minlength=1))
        for c, nodes in seen.items():
            self.nodes_by_channel.setdefault(fb.channel_label(c), set()).update(nodes.tolist())

    def _sdo(self, batch: DecodedBatch) -> None:
        """Result counts and latencies per node (and per bus and node on a log of several
        buses), from the batch's SDO records as columns."""
        tab = batch.records.table()
        if tab.node.size == 0:
            return
        nk = tab.node_keys
        _sdo_into(tab, tab.node, lambda i: nk[tab.node[i]], self.sdo_results, self.sdo_latency)
        if not batch.several:
            return
        buses = batch.record_buses(tab.slots)
        buses[np.equal(buses, None)] = self.first_bus  # made before the second bus was seen
        bus_code, distinct = first_seen_codes(buses.tolist())
        keys = tab.node * len(distinct) + bus_code
        _sdo_into(
            tab,
            keys,
            lambda i: (buses[i], nk[tab.node[i]]),
            self.sdo_results_by_bus,
            self.sdo_latency_by_bus,
        )

    def _evidence(self, batch: DecodedBatch) -> None:
        """Count frames whose shape says CANopen or says otherwise (CiA 301 sizes and values)."""
        fb = batch.frames
        svc = batch.service
        data_frame = (fb.flags & (FLAG_RTR | FLAG_ERR)) == 0
        std = (fb.flags & FLAG_EXT) == 0
        self.ext_frames += int((~std).sum())
        ids = fb.can_id & 0x7FF
        sdo = data_frame & std & ((svc == Service.SDO_REQUEST) | (svc == Service.SDO_RESPONSE))
        self.sdo_frames += int(sdo.sum())
        self.sdo_bad += np.bincount(ids[sdo & (fb.dlc != 8)], minlength=2048)
        ec = np.flatnonzero(  # the frames of the wrong length are evidence too
            data_frame
            & std
            & (
                (svc == Service.HEARTBEAT)
                | (svc == Service.BOOTUP)
                | (svc == Service.ERRCTL_INVALID)
            )
        )
        self.ec_frames += int(ec.size)
        state_ok = _IS_STATE[fb.data[ec, 0]]  # the byte tables only for the rows concerned
        self.ec_bad += np.bincount(ids[ec[(fb.dlc[ec] != 1) | ~state_ok]], minlength=2048)
        lss_rows = np.flatnonzero(data_frame & (svc == Service.LSS_MASTER) & (fb.dlc == 8))
        self.lss_good += int(_IS_LSS[fb.data[lss_rows, 0]].sum())
        nmt = np.flatnonzero(data_frame & (svc == Service.NMT) & (fb.dlc == 2))
        self.nmt_good += int((_IS_COMMAND[fb.data[nmt, 0]] & (fb.data[nmt, 1] < 128)).sum())

    @property
    def duration(self) -> float:
        if self.t_first is None or self.t_last is None:
            return 0.0
        return self.t_last - self.t_first

    def canopen_verdict(self) -> str | None:
        """Sentences when (part of) the traffic does not look like CANopen, else None.

        Evidence, not identifier ranges alone: every bus has frames whose
        identifiers fall into CANopen ranges, so the verdict also checks their
        shape (CiA 301: SDO frames are 8 bytes, heartbeats 1 byte with an NMT
        state) and how SDO transactions end on each channel.
        """
        if self.frames == 0:
            return "The log holds no frames."
        out: list[str] = []
        n = self.frames
        if self.ext_frames / n > 0.5:
            out.append(
                f"This does not look like CANopen: {self.ext_frames} of {n} frames have 29-bit identifiers "
                "(J1939 or another protocol); CANopen uses 11-bit identifiers."
            )
        ec_bad = int(self.ec_bad.sum())
        if ec_bad >= 3 and ec_bad > self.ec_frames / 2:
            out.append(
                f"Not CANopen error control: {ec_bad} of {self.ec_frames} frames on heartbeat identifiers "
                f"({_ids(self.ec_bad)}) are not 1 byte holding an NMT state."
            )
        sdo_bad = int(self.sdo_bad.sum())
        if sdo_bad >= 3 and sdo_bad > self.sdo_frames / 2:
            out.append(
                f"Not SDO: {sdo_bad} of {self.sdo_frames} frames on SDO identifiers ({_ids(self.sdo_bad)}) "
                "are not 8 bytes long (a proprietary protocol on these identifiers?)."
            )
        for node, total, errors in self._bad_sdo_channels():
            out.append(
                f"Node {node}'s SDO channel is probably not SDO: {errors} of {total} transactions "
                "are protocol errors."
            )
        good = (self.ec_frames - ec_bad) + (self.sdo_frames - sdo_bad) + self.nmt_good
        good += self.lss_good
        other = int(self.by_service[Service.OTHER]) + int(self.by_service[Service.ERROR_FRAME])
        if not out and other / n > 0.5 and good == 0:
            out.append(
                f"This does not look like CANopen: {other} of {n} frames use identifiers outside the "
                "predefined connection set, and no frame is a well-formed heartbeat, boot-up, NMT or SDO frame."
            )
        elif not out and good == 0 and n > 200:
            out.append(
                f"This may not be CANopen: no well-formed heartbeat, boot-up, NMT or SDO frame in {n} frames; "
                "identifiers merely fall into CANopen ranges."
            )
        return " ".join(out) or None

    def _bad_sdo_channels(self) -> list[tuple[int, int, int]]:
        out = []
        for node, results in sorted(self.sdo_results.items(), key=lambda kv: str(kv[0])):
            total, errors = sum(results.values()), results.get("protocol_error", 0)
            if total >= 3 and errors > total / 2:
                out.append((node, total, errors))
        return out

    def channel_load(self, name: str, bitrate: int | None) -> float | None:
        """Mean bus load of one channel in percent (nominal bits), None without a bitrate."""
        if not bitrate or self.duration <= 0 or name not in self.by_channel:
            return None
        return self.by_channel[name][1] / (bitrate * self.duration) * 100

    def channel_lines(self, bitrate: int | None = None) -> list[str]:
        """Frames and mean bus load of each channel (several buses in one log or session)."""
        out = []
        for name, (frames, _) in self.by_channel.items():
            load = self.channel_load(name, bitrate)
            shown = "" if load is None else f"  bus load {load:.1f} %"
            out.append(f"  {name:<15} {frames:>10}{shown}")
        return out

    def record(self, bitrate: int | None = None, problems: int = 0) -> dict:
        """The summary as one JSON-ready dict (`decode --summary --format jsonl`)."""
        load = None
        if bitrate and self.duration > 0:
            load = round(self.bits / (bitrate * self.duration) * 100, 3)
        nodes = _node_counts(self.by_node_service)
        sdo = {
            str(node): _sdo_entry(self.sdo_results[node], self.sdo_latency.get(node))
            for node in sorted(self.sdo_results, key=lambda x: (x is None, x))
        }
        several = {}
        if self.node_service_by_bus:  # a log of several buses: each bus's nodes too
            several["frames_per_node_by_bus"] = {
                bus: _node_counts(counts) for bus, counts in self.node_service_by_bus.items()
            }
            by_bus: dict = {}
            for bus, node in self._sdo_bus_keys():
                key = (bus, node)
                entry = _sdo_entry(self.sdo_results_by_bus[key], self.sdo_latency_by_bus.get(key))
                by_bus.setdefault(bus, {})[str(node)] = entry
            several["sdo_by_bus"] = by_bus
        loads = self.load.shares(bitrate)
        if loads:  # with a bitrate: each node's share, the longest burst (per bus: several)
            many = len(loads) > 1
            per = {
                name: {str(n): round(v, 3) for n, v in nodes.items()}
                for name, nodes in loads.items()
            }
            bursts = dict(self.load.bursts)
            several["bus_load_percent_per_node"] = per if many else next(iter(per.values()))
            several["longest_burst"] = bursts if many else next(iter(bursts.values()), None)
        if self.lss_steps:  # CiA 305: who got which node-ID (load().lss has every step)
            several["lss_assignments"] = list(self.lss_assignments)
        return {
            "kind": "summary",
            "frames": self.frames,
            "t_first": self.t_first,
            "t_last": self.t_last,
            "duration": round(self.duration, 6),
            "bitrate": bitrate,
            "bus_load_percent": load,
            "skipped_input": problems,
            "frames_per_service": {
                name: int(self.by_service[i])
                for i, name in enumerate(SERVICE_NAMES)
                if self.by_service[i]
            },
            "frames_per_node": nodes,
            "sdo": sdo,
            **several,
            "verdict": self.canopen_verdict(),
        }

    def _sdo_bus_keys(self) -> list[tuple]:
        """(bus, node) of the SDO transactions per bus: buses as first seen, nodes in order."""
        rank = {bus: i for i, bus in enumerate(self.node_service_by_bus)}
        return sorted(
            self.sdo_results_by_bus,
            key=lambda k: (rank.get(k[0], len(rank)), str(k[0]), k[1] is None, k[1] or 0),
        )

    def lines(self, bitrate: int | None = None, problems: int = 0, timed: bool = True) -> list[str]:
        """The summary's text; `timed` False: the log has no timestamps, so no duration,
        bus load nor latency is known (none is printed as 0)."""
        duration = f"{self.duration:.6f} s" if timed else "not known (the log has no timestamps)"
        out = [f"frames: {self.frames}", f"duration: {duration}"]
        if bitrate and self.duration > 0:
            load = self.bits / (bitrate * self.duration) * 100
            out.append(f"bus load: {load:.1f} % at {bitrate} bit/s (nominal bits, no stuff bits)")
        elif bitrate:
            out.append("bus load: n/a (no duration)")
        if problems:
            out.append(f"skipped input lines/records: {problems}")
        if len(self.by_channel) > 1:
            out.append("frames per channel:")
            out.extend(self.channel_lines(bitrate))
        out.append("frames per service:")
        for i, name in enumerate(SERVICE_NAMES):
            if self.by_service[i]:
                out.append(f"  {name:<15} {int(self.by_service[i]):>10}")
        if self.node_service_by_bus:  # node 5 on can0 and on can1: two devices
            node_lines = [
                _node_line(f"{bus} node", n, counts[n])
                for bus, counts in self.node_service_by_bus.items()
                for n in np.flatnonzero(counts.sum(axis=1)).tolist()
            ]
        else:
            node_lines = [
                _node_line("node", n, self.by_node_service[n])
                for n in np.flatnonzero(self.by_node_service.sum(axis=1)).tolist()
            ]
        if node_lines:
            out += ["frames per node:", *node_lines]
        if self.sdo_results_by_bus:
            out.append("SDO transactions per node:")
            for key in self._sdo_bus_keys():
                results, lat = self.sdo_results_by_bus[key], self.sdo_latency_by_bus.get(key)
                out.append(_sdo_line(f"{key[0]} node {key[1]}", results, lat if timed else None))
        elif self.sdo_results:
            out.append("SDO transactions per node:")
            for node in sorted(self.sdo_results, key=lambda x: (x is None, x)):
                lat = self.sdo_latency.get(node)
                out.append(
                    _sdo_line(f"node {node}", self.sdo_results[node], lat if timed else None)
                )
        out += self.load.lines(bitrate, timed)
        out += self.lss_lines()
        verdict = self.canopen_verdict()
        if verdict:
            out.append(verdict)
        return out

    def lss_lines(self) -> list[str]:
        """LSS (CiA 305): the steps seen, and who got which node-ID."""
        steps = self.lss_steps
        if not steps:
            return []
        out = [f"LSS: {steps} steps (load().lss lists them)"]
        for a in self.lss_assignments:
            stored = " (stored)" if a["stored"] else " (not stored)"
            out.append(f"LSS: node-ID {a['node_id']} given to {identity_text(a)}{stored}")
        return out


def _seen_nodes(model, summary: Summary | None, bus: str | None) -> list[int]:
    """The nodes a device line is given for: declared or identified in `model`, and those
    seen (on `bus` only, when the log has several)."""
    seen = set(getattr(model, "nodes", {}))
    if summary is not None and bus is None:
        seen |= {int(n) for n in np.flatnonzero(summary.by_node_service.sum(axis=1))}
    elif summary is not None:
        seen |= summary.nodes_by_channel.get(bus, set())
    return sorted(seen)


def device_lines(model, summary: Summary | None = None, bus: str | None = None) -> list[str]:
    """Each node seen or declared: its device and how it was identified (`bus`: one bus's
    of a log of several, its own network model; the lines name it, no header)."""
    known = dict(getattr(model, "nodes", {}))
    who = "node" if bus is None else f"{bus} node"
    out = []
    for node in _seen_nodes(model, summary, bus):
        cfg = known.get(node)
        if cfg is None:
            out.append(
                f"  {who} {node:>3}: unknown device (no identity read in the log; give --device or --eds)"
            )
            continue
        seen = ", ".join(
            f"{k} 0x{v:X}" if isinstance(v, int) else f"{k} {v!r}"
            for k, v in sorted(cfg.identity.items())
        )
        if cfg.profile is None:  # not "unknown device (identified by unknown)"
            line = f"  {who} {node:>3}: unknown device (no profile matches what the log shows)"
        else:
            line = f"  {who} {node:>3}: {cfg.profile.name} (identified by {cfg.identified_by})"
        out.append(line + (f"; seen {seen}" if seen else ""))
    if bus is not None:
        return out
    return ["devices:", *out] if out else []


def bus_device_lines(networks: dict, summary: Summary | None = None) -> list[str]:
    """`device_lines` of every bus (`Decoder.networks`): each bus's devices from its own
    network model ("can1 node 5"); one bus: as `device_lines`."""
    if list(networks) == [None]:
        return device_lines(networks[None], summary)
    out = [line for bus, model in networks.items() for line in device_lines(model, summary, bus)]
    return ["devices:", *out] if out else []


class SummarySink(Sink):
    """`decode --summary`: counts while the log is read, the report at the end, as text or
    (with `--format jsonl`) one JSON object of kind "summary"."""

    def __init__(self, out: TextIO, fmt: str = "text") -> None:
        self.out = out
        self.fmt = fmt
        self.summary = Summary()

    def write(self, batch: DecodedBatch) -> None:
        self.summary.add(batch)

    def close(self) -> None:
        run = self.run
        bitrate = run_bitrate(run)
        checker = run.checker
        if self.fmt == "jsonl":
            import json

            rec = self.summary.record(bitrate, run.problems.count)
            rec["devices"] = bus_device_records(run.decoder.networks(), self.summary)
            if checker is not None:
                rec["timing"] = _plain(checker.timing.report(checker.nmt))
                if checker.others:  # several buses: "timing" is the first's, here each
                    rec["timing_by_bus"] = {
                        c.bus: _plain(c.timing.report(c.nmt)) for c in (checker, *checker.others)
                    }
            print(json.dumps(rec, separators=(",", ":"), ensure_ascii=False), file=self.out)
            return
        timed = checker is None or checker.timed is not False
        lines = self.summary.lines(bitrate, run.problems.count, timed)
        lines += bus_device_lines(run.decoder.networks(), self.summary)
        if checker is not None:
            lines += checker.timing_lines(checker.t0)
        print("\n".join(lines), file=self.out)


def _plain(value):
    """JSON-safe: dict keys as strings, numpy scalars as Python, NaN as null."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and value != value:
        return None
    return value


def bus_device_records(networks: dict, summary: Summary | None = None) -> list[dict]:
    """`device_records` of every bus, each record with its `bus` on a log of several."""
    if list(networks) == [None]:
        return device_records(networks[None], summary)
    return [r for bus, m in networks.items() for r in device_records(m, summary, bus)]


def device_records(model, summary: Summary | None = None, bus: str | None = None) -> list[dict]:
    """`device_lines` as records: node, device, how it was identified, identity seen
    (and `bus`, given one of a log of several)."""
    known = dict(getattr(model, "nodes", {}))
    out = []
    for node in _seen_nodes(model, summary, bus):
        cfg = known.get(node)
        prof = cfg.profile if cfg is not None else None
        out.append(
            {
                "node": node,
                "device": prof.name if prof is not None else None,
                "profile": prof.key if prof is not None else None,
                "identified_by": cfg.identified_by if cfg is not None else None,
                "identity": _plain(dict(cfg.identity)) if cfg is not None else {},
            }
        )
        if bus is not None:
            out[-1]["bus"] = bus
    return out


def _sdo_into(tab, codes: np.ndarray, key_of, results_by: dict, latency_by: dict) -> None:
    """Add an SdoTable's result counts and latencies into `results_by` and `latency_by`,
    per distinct code, under `key_of(position of its first record)`; dict order as a
    loop over the records gives."""
    rk = tab.result_keys
    for _, at in tab.groups(codes):
        results = results_by.setdefault(key_of(at[0]), {})
        res = tab.result[at]
        if len(rk) == 1:
            results[rk[0]] = results.get(rk[0], 0) + res.size
            continue
        counts = np.bincount(res, minlength=len(rk)).tolist()
        for r in tab.first_seen(res):
            results[rk[r]] = results.get(rk[r], 0) + counts[r]
    for _, at in tab.groups(codes, ~np.isnan(tab.latency)):
        key = key_of(at[0])
        st = latency_by.get(key)
        if st is None:
            st = latency_by[key] = StreamStats()
        st.add(tab.latency[at])


def _node_counts(counts: np.ndarray) -> dict:
    """{node: {service: frames}} of a (128, N_SVC) count table, nodes with frames only."""
    return {
        str(n): {SERVICE_NAMES[s]: int(c) for s, c in enumerate(counts[n]) if c}
        for n in np.flatnonzero(counts.sum(axis=1)).tolist()
    }


def _node_line(who: str, node: int, counts: np.ndarray) -> str:
    parts = [f"{SERVICE_NAMES[s]}={int(c)}" for s, c in enumerate(counts) if c]
    return f"  {who} {node:>3}: {int(counts.sum()):>8}  " + " ".join(parts)


def _sdo_entry(results: dict, lat: StreamStats | None) -> dict:
    """One node's SDO transactions in the summary's JSON: result counts, latency."""
    entry: dict = {"results": dict(sorted(results.items()))}
    if lat is not None and lat.n:
        entry["latency_ms"] = {"min": lat.min, "median": lat.quantile(0.5), "max": lat.max}
    return entry


def _sdo_line(who: str, results: dict, lat: StreamStats | None) -> str:
    text = (
        f"  {who}: {sum(results.values())} ("
        + ", ".join(f"{k} {v}" for k, v in sorted(results.items()))
        + ")"
    )
    if lat is not None and lat.n:
        text += f"; latency ms min {lat.min:.2f} median {lat.quantile(0.5):.2f} max {lat.max:.2f}"
    return text
