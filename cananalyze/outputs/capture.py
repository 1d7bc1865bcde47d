"""Capture: a whole decoded log as columns, for pandas and the timeline exporters.

`load()` runs the same pipeline as `decode` and keeps what it produced as numpy
columns (frames, PDO signal series per node and PDO) plus the rare, stateful
results as small lists (SDO transactions, events, findings). DataFrames are built
from those columns on first access, so exporters that do not need pandas never
import it (`cananalyze --help` stays fast, MCAP/rerun export skip 0.5 s of imports).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cananalyze.core.errors import ProblemLog
from cananalyze.core.frames import FrameBatch, concat
from cananalyze.core.records import DecodedBatch
from cananalyze.decode.boot import BootFollower, declared_identity
from cananalyze.decode.events.build import LEVEL_NAMES, Event, EventState, batch_events_of
from cananalyze.decode.lss import PARTS as LSS_PARTS
from cananalyze.decode.lss import LssFollower
from cananalyze.decode.node_tally import NodeTally
from cananalyze.decode.od_tally import OdTally
from cananalyze.outputs import schemas
from cananalyze.pipeline.sink import Sink
from cananalyze.protocol.services import SERVICE_NAMES, Service

if TYPE_CHECKING:
    import pandas as pd


@dataclass
class SignalSeries:
    """All decoded values of one PDO of one node, over the whole log."""

    node: int
    pdo: str
    cob_id: int
    t: np.ndarray
    rows: np.ndarray  # frame rows in Capture.batch
    columns: dict[str, np.ndarray]
    units: dict[str, str | None]
    bus: str | None = None  # a log of several buses: which one (node 5 on can1 is its own)
    objects: dict[str, tuple[int, int]] = field(default_factory=dict)  # signal -> (index, sub)

    @property
    def key(self) -> str:
        return (
            f"{self.node}/{self.pdo}" if self.bus is None else f"{self.bus}/{self.node}/{self.pdo}"
        )


@dataclass
class Capture:
    """A decoded log: raw columns plus tables built on demand."""

    source: str
    batch: FrameBatch
    service: np.ndarray
    node: np.ndarray
    pdo: np.ndarray
    series: list[SignalSeries]
    records: list[tuple[int, dict]]
    event_list: list[Event]
    state_changes: list[Event]  # kind nmt_state, message = state name
    problems: ProblemLog
    network: str = ""
    profiles: dict[int, tuple[str, str]] = field(default_factory=dict)  # node -> (profile, how)
    # several buses: bus -> its own network model's profiles (a device identified on can1)
    bus_profiles: dict[str, dict[int, tuple[str, str]]] = field(default_factory=dict)
    checker: Any = None  # the Checker that ran in the pipeline (load() attaches one)
    options: Any = None  # the pipeline Options it was decoded with
    drive_changes: list = field(default_factory=list)  # CiA 402 (network.drive_tracker)
    # a log of several buses: each record's bus (None: made before a second bus was seen,
    # the first bus's); None on a log of one bus
    record_bus: list | None = None
    # (bus, decode.commissioning.Commissioning) of each bus when the log was decoded here:
    # the run's boot stories and LSS steps (`boot`, `lss`), not followed a second time
    commissioning: list = field(default_factory=list)
    # each frame's time after the SYNC before it (ms) for synchronous PDOs, NaN elsewhere;
    # None: no such frame (the frames table's sync_latency_ms)
    sync_late: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.batch)

    def __repr__(self) -> str:
        t = self.batch.t
        span = float(t[-1] - t[0]) if t.size else 0.0
        nodes = np.unique(self.node[self.node >= 0]).tolist()
        sdo = sum(1 for _, r in self.records if r.get("kind") == "sdo")
        findings = len(self.checker.findings) if self.checker is not None else 0
        shown = ", ".join(map(str, nodes[:12])) + (" ..." if len(nodes) > 12 else "")
        return (
            f"<Capture {Path(str(self.source)).name}: {len(self):,} frames over {span:.3f} s; "
            f"nodes {shown or '-'}; {len(self.series)} PDO series, {sdo} SDO transfers, "
            f"{len(self.event_list)} events, {findings} findings>"
        )

    # --- tables -------------------------------------------------------------
    @cached_property
    def frames(self) -> pd.DataFrame:
        """One row per frame: t, channel, can_id, dlc, data (bytes), flags, service, node, pdo.

        `data` is the payload as bytes (pandas' `binary[pyarrow]`), as the Parquet file
        holds it; `data_hex()` gives the same payloads as lowercase hex text (the CSV's).
        """
        import pandas as pd

        from cananalyze.core.columns.payloads import payload_bytes

        fb = self.batch
        channels = list(fb.channels) or ["can0"]
        chan_codes = np.minimum(fb.channel, len(channels) - 1).astype(np.int32)
        return _table(
            pd,
            schemas.FRAMES,
            {
                "t": fb.t,
                "channel": pd.Categorical.from_codes(chan_codes, categories=channels),
                "can_id": fb.can_id,
                "dlc": fb.dlc,
                "data": pd.Series(pd.arrays.ArrowExtensionArray(payload_bytes(fb)), copy=False),
                "flags": fb.flags,
                "service": pd.Categorical.from_codes(
                    self.service.astype(np.int16), categories=list(SERVICE_NAMES)
                ),
                "node": pd.arrays.IntegerArray(self.node.astype(np.int16), self.node < 0),
                "pdo": pd.arrays.IntegerArray(self.pdo.astype(np.int8), self.pdo == 0),
                "sync_latency_ms": np.full(len(fb), np.nan)
                if self.sync_late is None
                else self.sync_late,
            },
        )

    def data_hex(self) -> pd.Series:
        """`frames.data` as lowercase hex text ("" for a remote frame), built from the
        payload columns in one pass (a `.map(bytes.hex)` makes a Python string per frame)."""
        import pandas as pd

        from cananalyze.core.columns.payloads import payload_hex

        arr = pd.arrays.ArrowExtensionArray(payload_hex(self.batch))
        return pd.Series(arr, name="data", copy=False)

    @cached_property
    def drive_states(self) -> pd.DataFrame:
        """Each CiA 402 axis's state timeline: t, node, state, statusword, source, row
        (one row per state entered; source "tpdo1", "sdo", ...), and bus on a log of
        several buses (node 1 on can0 and node 1 on can1 are two drives)."""
        return self._drive_table("state", "statusword")

    @cached_property
    def drive_commands(self) -> pd.DataFrame:
        """Each CiA 402 axis's commands: t, node, command, controlword, source, row (and
        bus, as drive_states)."""
        return self._drive_table("command", "controlword")

    def _drive_table(self, kind: str, word: str) -> pd.DataFrame:
        import pandas as pd

        rows = [c for c in self.drive_changes if c.kind == kind]
        df = pd.DataFrame(
            {
                "t": np.array([c.t for c in rows], np.float64),
                "node": np.array([c.node for c in rows], np.int16),
                kind: pd.Series([c.name for c in rows], dtype=object),
                word: np.array([c.word for c in rows], np.uint16),
                "source": pd.Series([c.source for c in rows], dtype=object),
                "row": np.array([c.row for c in rows], np.int64),
            }
        )
        if any(c.bus is not None for c in rows):  # several buses: which one, last (as events)
            df["bus"] = _buses([c.bus for c in rows], self._first_bus())
        return df

    @cached_property
    def signals(self) -> pd.DataFrame:
        """Long table of PDO values: t, node, pdo, cob_id, signal, value, unit.

        `value` is float64 for every signal so that one column can be plotted and
        aggregated: integers beyond 2**53 (UNSIGNED64/INTEGER64 objects) lose their low
        bits here. The exact integers are in `series[k].columns` (their own dtype) and
        in the MCAP payloads. `unit` is "" for signals without a unit.
        """
        import pandas as pd

        parts: dict[str, list[np.ndarray]] = {k: [] for k in ("t", "node", "cob", "code", "value")}
        names: list[str] = []
        pdos: list[str] = []
        units: list[str | None] = []
        buses: list[str | None] = []
        for s in self.series:
            for name, values in s.columns.items():
                n = len(values)
                parts["t"].append(s.t)
                parts["node"].append(np.full(n, s.node, np.int16))
                parts["cob"].append(np.full(n, s.cob_id, np.uint32))
                parts["code"].append(np.full(n, len(names), np.int32))
                parts["value"].append(np.asarray(values, np.float64))
                names.append(name)
                pdos.append(s.pdo)
                units.append(s.units.get(name))
                buses.append(s.bus)
        if not names:
            return _table(
                pd,
                schemas.SIGNALS,
                {
                    "t": np.zeros(0),
                    "node": np.zeros(0, np.int16),
                    "pdo": pd.Categorical([]),
                    "cob_id": np.zeros(0, np.uint32),
                    "signal": pd.Categorical([]),
                    "value": np.zeros(0),
                    "unit": pd.Categorical([]),
                },
            )
        code = np.concatenate(parts["code"])
        t = np.concatenate(parts["t"])
        order = np.argsort(t, kind="stable")
        code = code[order]
        df = _table(
            pd,
            schemas.SIGNALS,
            {
                "t": t[order],
                "node": np.concatenate(parts["node"])[order],
                "pdo": _categorical(pd, code, pdos),
                "cob_id": np.concatenate(parts["cob"])[order],
                "signal": _categorical(pd, code, names),
                "value": np.concatenate(parts["value"])[order],
                "unit": _categorical(pd, code, [u or "" for u in units]),
            },
        )
        if any(b is not None for b in buses):  # several buses: which one, last (as events)
            df["bus"] = np.asarray(buses, object)[code]
        return df

    @cached_property
    def signals_by_frame(self) -> pd.DataFrame:
        """signals.parquet's layout: one row per PDO frame (t, node, pdo, cob_id), a float64
        column per signal, null where the row's PDO does not carry it (`outputs/tables/wide`
        names the columns; `signals` is the same values one row per value)."""
        from cananalyze.outputs.tables import wide

        names = wide.SignalColumns()
        pdos = sorted({s.pdo for s in self.series})
        code = {p: i for i, p in enumerate(pdos)}
        buses = list(dict.fromkeys(s.bus for s in self.series if s.bus is not None))
        bus = {b: i for i, b in enumerate(buses)}
        parts = [
            (s.rows, s.node, code[s.pdo], s.cob_id, k, s.columns, s.units, bus.get(s.bus, -1))
            for k, s in enumerate(self.series)  # sorted by node, PDO, COB-ID: the rank
            if len(s.rows)
        ]
        if not parts:
            return wide.arrow_table(wide.empty_rows(), [], wide.schema(names)).to_pandas()
        rows = wide.frame_rows(self.batch.t, parts, names)
        return wide.arrow_table(rows, pdos, wide.schema(names, bool(buses)), buses).to_pandas()

    def signals_wide(self) -> pd.DataFrame:
        """Time index, one column per `node/pdo/signal`; NaN where a PDO was not sent. A
        log without times (every frame at one time: candump's screen output) is indexed
        by `line` instead: one time would fold every value into one row."""
        import pandas as pd

        fb = self.batch
        untimed = len(fb) > 1 and float(fb.t.min()) == float(fb.t.max())
        key = "line" if untimed else "t"
        if not self.series:
            return pd.DataFrame(index=pd.Index([], name=key, dtype=float))
        at = [fb.line[s.rows] if untimed else s.t for s in self.series]
        index = np.unique(np.concatenate(at))
        cols: dict[str, np.ndarray] = {}
        for s, when in zip(self.series, at, strict=True):
            pos = np.searchsorted(index, when)
            for name, values in s.columns.items():
                col = np.full(index.size, np.nan)
                col[pos] = np.asarray(values, np.float64)  # same time twice: the last wins
                cols[f"{s.key}/{name}"] = col
        return pd.DataFrame(cols, index=pd.Index(index, name=key))

    @cached_property
    def sdo(self) -> pd.DataFrame:
        """The SDO transaction records, one row each, in completion order."""
        import pandas as pd

        cols = [c for c in schemas.SDO.names if c != "bus"]
        at = [k for k, (_, r) in enumerate(self.records) if r.get("kind") == "sdo"]
        recs = [self.records[k][1] for k in at]
        df = pd.DataFrame.from_records(recs, columns=cols) if recs else pd.DataFrame(columns=cols)
        if "value" in df:
            df["value"] = df["value"].astype(object)  # mixed ints, floats, strings
        if self.record_bus is not None:  # several buses: which one, last (as the events)
            df["bus"] = _buses([self.record_bus[k] for k in at], self._first_bus())
        return df

    @cached_property
    def events(self) -> pd.DataFrame:
        """NMT commands, EMCY, boot-ups, NMT state changes, SDO transactions, findings."""
        return _event_frame(self.sorted_events(), self._first_bus())

    def _first_bus(self) -> str | None:
        """The first frame's bus: what events built before a second bus was seen are on."""
        fb = self.batch
        return fb.channel_label(int(fb.channel[0])) if len(fb) else None

    def sorted_events(self) -> list[Event]:
        """Events by time, then by frame row (logs without timestamps have t = 0 throughout)."""
        big = len(self.batch)
        return sorted(self.event_list, key=lambda e: (e.t, big if e.row is None else e.row))

    @cached_property
    def findings(self) -> pd.DataFrame:
        """Rule violations, one row each by time: the same Checker and records as
        `cananalyze check` (t absolute, t_rel from the first frame, measured, expected, why, basis: where
        the expected value came from, line: in a log without times)."""
        import pandas as pd

        cols = [c for c in schemas.FINDINGS.names if c != "bus"]
        if self.checker is not None:  # read as columns: no Finding object per row
            found = self.checker.findings
            found = found.take(np.argsort(np.asarray(found.column("t")), kind="stable"))
            if np.not_equal(found.bus, None).any():
                cols.append("bus")  # several buses: which one
            recs: list = list(zip(*(found.column(c) for c in cols), strict=True))
        else:
            recs = [r for _, r in self.records if r.get("kind") == "finding"]
            if any("bus" in r for r in recs):
                cols.append("bus")
                recs = [tuple(r.get(c) for c in cols) for r in recs]
        df = pd.DataFrame.from_records(recs, columns=cols) if recs else pd.DataFrame(columns=cols)
        for c in ("node", "cob_id", "line"):
            df[c] = df[c].astype("Int64")
        return df

    # --- statistics and assertions for tests -------------------------------------
    def heartbeat(self, node: int, bus: str | None = None) -> dict:
        """Heartbeat gaps of one node in ms: count, min, median, mean, p99, max, jitter
        (the numbers of `check --timing`; {"count": 0} with fewer than two heartbeats).

        On a log of several buses the node on each bus is its own device: `bus` (a
        channel name) says which, and is needed when the node beats on more than one."""
        from cananalyze.checks.streamstats import stats
        from cananalyze.core.errors import UsageError

        fb = self.batch
        mine = (self.service == Service.HEARTBEAT) & (self.node == node)
        channels = np.unique(fb.channel[mine]).tolist()
        if bus is not None:
            names = {fb.channel_label(c): c for c in np.unique(fb.channel).tolist()}
            if bus not in names:
                known = ", ".join(names) or "none"
                raise UsageError(f"no bus {bus!r} in this log (its buses: {known})")
            mine &= fb.channel == names[bus]
        elif len(channels) > 1:
            names = ", ".join(fb.channel_label(c) for c in channels)
            raise UsageError(f"node {node} beats on several buses ({names}): give bus=")
        t = fb.t[mine]
        # to the microsecond: epoch-second floats carry sub-us noise into every gap
        return {k: round(v, 3) if isinstance(v, float) else v for k, v in stats(np.diff(t)).items()}

    def _blocks(self) -> list:
        """The signal series as blocks of the whole capture (their mapped objects too)."""
        from cananalyze.core.records import SignalBlock

        return [
            SignalBlock(
                s.rows, s.node, s.pdo, s.cob_id, s.columns, s.units, objects=dict(s.objects)
            )
            for s in self.series
        ]

    def decoded(self) -> list[DecodedBatch]:
        """The whole capture as one DecodedBatch again, for rules run after the fact."""
        blocks = self._blocks()
        return [
            DecodedBatch(
                self.batch, self.service, self.node, self.pdo, records=self.records, signals=blocks
            )
        ]

    @property
    def config(self):
        """What the checks compare against (network file, rules file, SDO writes, profiles)."""
        return self.checker.config if self.checker is not None else None

    @cached_property
    def nodes(self) -> pd.DataFrame:
        """Per node: frame counts, last NMT state, identity read by SDO, profile and how."""
        import pandas as pd

        return pd.DataFrame.from_records(self.node_rows(), index="node")

    @cached_property
    def sync_latency(self) -> pd.DataFrame:
        """Per synchronous PDO (transmission type 0-240): its latency after SYNC in ms
        (count, min, median, mean, p99, max, jitter), the window 0x1007 in force at its
        last frame and the margin left (window - max); `bus` on a log of several buses."""
        import pandas as pd

        checkers = [] if self.checker is None else [self.checker, *self.checker.others]
        rows = []
        for c in checkers:
            for cob, s in c.timing.report()["sync_latency"].items():
                row = {"cob_id": cob, **{k: s.get(k) for k in _SYNC_LATENCY}}
                if len(checkers) > 1:
                    row["bus"] = c.bus
                rows.append(row)
        bus = ["bus"] if len(checkers) > 1 else []
        return pd.DataFrame.from_records(rows, columns=["cob_id", *_SYNC_LATENCY, *bus])

    @cached_property
    def boot(self) -> pd.DataFrame:
        """Each node's boot stories (a row per life): stopped or operational, the step it
        stopped at and its CiA 302-2 error status, the steps (decode/boot)."""
        import pandas as pd

        cols = ["node", "life", "t_boot", "result", "stopped_at", "status", "status_text"]
        cols += ["verdict", "steps"]
        if self.commissioning:  # the run's own stories
            several = len(self.commissioning) > 1
            rows = [
                s.as_row() | ({"bus": bus} if several else {})
                for bus, c in self.commissioning
                for s in c.stories
            ]
            return pd.DataFrame.from_records(rows, columns=cols + (["bus"] if several else []))
        follower = BootFollower()
        follower.add(
            DecodedBatch(self.batch, self.service, self.node, self.pdo, records=self.records)
        )
        config = self.config
        model = getattr(config, "model", None)
        hb = config.heartbeat_ms if config is not None and len(self.batch) and self._timed else None
        t_end = float(self.batch.t[-1]) if len(self.batch) else None
        stories = follower.stories(
            lambda n: declared_identity(model, n), hb, t_end, timed=self._timed
        )
        return pd.DataFrame.from_records([s.as_row() for s in stories], columns=cols)

    def _bitrate(self, bitrate: int | None) -> int | None:
        """The bitrate given, else the run's (`load(bitrate=)`), else the network file's."""
        if bitrate or getattr(self.options, "bitrate", None):
            return bitrate or self.options.bitrate
        model = getattr(self.config, "model", None)
        return getattr(getattr(model, "spec", None), "bitrate", None)

    def bus_load_per_node(self, bitrate: int | None = None) -> pd.DataFrame:
        """Per node (and `bus` on a log of several): the frames it sent itself (heartbeat,
        TPDO, EMCY, SDO response, guard response, boot-up), their nominal bits, and its
        mean share of the bus in percent at `bitrate` (else the network file's; NaN
        without one or without times), as `decode --summary` prints it."""
        import pandas as pd

        from cananalyze.decode.node_load import NodeLoad

        fb, rate = self.batch, self._bitrate(bitrate)
        load = NodeLoad()  # the computation --summary and --timing print
        if len(fb):
            load.add(DecodedBatch(fb, self.service, self.node, self.pdo))
        shares = load.shares(rate)
        channels = list(load.sent)
        rows = []
        for name, (frames, bits) in load.sent.items():
            for n in np.flatnonzero(frames).tolist():
                row = {"node": n, "frames": int(frames[n]), "bits": int(bits[n])}
                row["load_percent"] = shares.get(name, {}).get(n, float("nan"))
                if len(channels) > 1:
                    row["bus"] = name
                rows.append(row)
        cols = ["node", "frames", "bits", "load_percent", *(["bus"] if len(channels) > 1 else [])]
        return pd.DataFrame.from_records(rows, columns=cols)

    def longest_burst(self, bitrate: int | None = None) -> dict:
        """Per bus: the longest run of frames back to back ({frames, t_start, t_end}) at
        `bitrate` (else the network file's); {} without one or without times."""
        from cananalyze.protocol.busload import Bursts, bits_by_channel

        rate = self._bitrate(bitrate)
        if not rate or not self._timed:
            return {}
        out = {}
        for name, (t, bits) in bits_by_channel(self.batch).items():
            burst = Bursts(rate)
            burst.add(t, bits)
            out[name] = burst.record()
        return out

    @property
    def _timed(self) -> bool:
        return self.checker is None or self.checker.timed is not False

    @cached_property
    def _lss(self) -> tuple[list, list[dict]]:
        """(LSS events, assignments) of the whole log (decode/lss): the run's own."""
        if self.commissioning:
            events = [e for _, c in self.commissioning for e in c.lss_events]
            return events, [a for _, c in self.commissioning for a in c.assignments]
        follower = LssFollower()
        batch = DecodedBatch(self.batch, self.service, self.node, self.pdo)
        events = follower.add(batch) + follower.finish()
        return events, follower.assignments

    @cached_property
    def lss(self) -> pd.DataFrame:
        """LSS (CiA 305) steps: fastscans with the identity found, selective and global
        switches, configure node-ID / bit timing, store, inquiries; each with its result."""
        import pandas as pd

        cols = ["t", "step", "result", *LSS_PARTS, "node_id", "detail"]
        return pd.DataFrame.from_records([e.as_row() for e in self._lss[0]], columns=cols)

    @cached_property
    def lss_assignments(self) -> pd.DataFrame:
        """Which identity (vendor, product, revision, serial) got which node-ID by LSS,
        when, and whether the store that followed succeeded."""
        import pandas as pd

        cols = ["t", *LSS_PARTS, "node_id", "stored"]
        return pd.DataFrame.from_records(self._lss[1], columns=cols)

    @cached_property
    def od(self) -> pd.DataFrame:
        """Each node's objects as its successful SDO transfers showed them, per life
        (boot-ups split it): last value, when and how set, how often, what it went through;
        PDO-mapped objects' last values too (`set_by` "pdo")."""
        import pandas as pd

        tally = OdTally()
        tally.add(
            DecodedBatch(
                self.batch,
                self.service,
                self.node,
                self.pdo,
                records=self.records,
                signals=self._blocks(),
            )
        )
        rows = tally.rows()
        names = list(rows[0]) if rows else list(schemas.OD.without("bus").names)
        return pd.DataFrame.from_records(rows, columns=names)

    def node_rows(self) -> list[dict]:
        """Plain rows of the nodes table (also used by MCAP metadata, without pandas)."""
        tally = NodeTally()
        fb, rate = self.batch, self._bitrate(None)
        if len(fb) and (fb.channel != fb.channel[0]).any():  # several buses: one row each
            decoded = DecodedBatch(fb, self.service, self.node, self.pdo, records=self.records)
            tally.add(decoded, self.state_changes, 0)
            return tally.rows(self.profiles, self.bus_profiles, rate)
        tally.load.add(DecodedBatch(fb, self.service, self.node, self.pdo))
        tally.add_frames(self.service, self.node)
        tally.add_states(self.state_changes)
        tally.add_identity(self.records)
        return tally.rows(self.profiles, bitrate=rate)


_SYNC_LATENCY = ("node", "pdo", "type", "count", "min", "median", "mean", "p99", "max")
_SYNC_LATENCY += ("jitter", "window_ms", "margin_ms")


def _table(pd, table: schemas.Table, columns: dict):
    """A DataFrame of a declared table's columns, in their declared order; `bus` (last)
    is added by the caller on a log of several buses. A column built here that the
    declaration lacks, or the reverse, is a bug caught on the first load()."""
    names = [n for n in table.names if n != "bus"]
    if list(columns) != names:
        raise RuntimeError(f"{table.name}: built {list(columns)}, declared {names}")
    return pd.DataFrame(columns)


def _categorical(pd, codes: np.ndarray, labels: list[str]):
    """Categorical over possibly repeated labels: map codes onto the unique labels."""
    uniq, inverse = np.unique(np.array(labels, dtype=object), return_inverse=True)
    return pd.Categorical.from_codes(inverse[codes], categories=list(uniq))


def _event_frame(events: list[Event], first_bus: str | None = None):
    """The events table; a `bus` column (after the others) only on a log of several buses."""
    import pandas as pd

    df = _table(
        pd,
        schemas.EVENTS,
        {
            "t": np.array([e.t for e in events], np.float64),
            "kind": pd.Categorical([e.kind for e in events]),
            "node": pd.array([e.node for e in events], dtype="Int16"),
            "level": pd.Categorical(
                [LEVEL_NAMES[e.level] for e in events], categories=list(LEVEL_NAMES.values())
            ),
            "message": pd.array([e.message for e in events], dtype="string"),
            "row": pd.array([e.row for e in events], dtype="Int64"),
        },
    )
    if any(e.bus is not None for e in events):
        df["bus"] = _buses([e.bus for e in events], first_bus)
    return df


def _buses(buses: list, first: str | None) -> np.ndarray:
    """A table's `bus` column: each row's bus, the first bus's where it has none (made
    before a second bus was seen)."""
    out = np.array(buses, object)
    out[np.equal(out, None)] = first
    return out


class Collector:
    """Accumulates DecodedBatches; `capture()` joins them once at the end."""

    def __init__(
        self, source: str = "", event_state: EventState | None = None, records: bool = True
    ) -> None:
        """event_state: what event building carried from earlier batches, when this
        Collector takes over a log part-way (live and streamed Rerun, a batch or a
        flush at a time: NMT lanes show changes only, late findings keep their time).
        records=False: the Capture has no records (Rerun sends signals, states and
        events): the SDO fast path's records stay columns, not a dict each."""
        self.source = source
        self.keep_records = records
        self._frames: list[FrameBatch] = []
        self._cols: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        # (node, pdo, cob_id, signal names, bus) -> blocks; bus: the first frame's before a
        # second bus was seen (the same series after it), told only when blocks of several came
        self._blocks: dict[tuple[int, str, int, tuple[str, ...], str | None], list] = {}
        self._first_bus: str | None = None
        self._several_signals = False
        self.records: list[tuple[int, dict]] = []
        self.record_bus: list | None = None  # each record's bus, once a second bus is seen
        self.events: list[Event] = []
        self.states: list[Event] = []
        self.drive: list = []
        self.event_state = event_state or EventState()
        self.offset = 0

    def add(self, batch: DecodedBatch) -> None:
        fb = batch.frames
        off = self.offset
        if len(fb):
            self._frames.append(fb)
            self._cols.append((batch.service, batch.node, batch.pdo, batch.sync_latency))
            if self._first_bus is None:
                self._first_bus = fb.channel_label(int(fb.channel[0]))
        for blk in batch.signals:
            bus = batch.block_bus(blk)
            self._several_signals |= bus is not None
            key = (blk.node, blk.pdo, blk.cob_id, tuple(blk.columns), bus or self._first_bus)
            self._blocks.setdefault(key, []).append((fb.t[blk.rows], blk.rows + off, blk))
        if self.keep_records:
            if batch.several and self.record_bus is None:
                self.record_bus = [None] * len(self.records)  # before: the first bus's
            self.records.extend((row + off, rec) for row, rec in batch.records)
            if self.record_bus is not None:
                slots = np.arange(len(batch.records))
                self.record_bus.extend(batch.record_buses(slots).tolist())
        cols, states = batch_events_of(batch, off, self.event_state)
        self.events.extend(Event(*e) for e in cols.rows())
        self.states.extend(Event(*e) for e in states)
        self.drive.extend(c._replace(row=c.row + off) for c in batch.drive)
        self.offset += len(fb)

    def capture(
        self,
        problems: ProblemLog,
        network: str = "",
        profiles: dict[int, tuple[str, str]] | None = None,
        cls: type[Capture] | None = None,
    ) -> Capture:
        """The collected columns as one Capture (`cls`: the API's subclass, for `load()`)."""
        fb = concat(self._frames) if self._frames else FrameBatch.empty()
        if self._cols:
            service = np.concatenate([c[0] for c in self._cols])
            node = np.concatenate([c[1] for c in self._cols])
            pdo = np.concatenate([c[2] for c in self._cols])
            sync = None
            if any(c[3] is not None for c in self._cols):
                sync = np.concatenate(
                    [np.full(len(c[0]), np.nan) if c[3] is None else c[3] for c in self._cols]
                )
        else:
            sync = None
            service = np.zeros(0, np.uint8)
            node = np.zeros(0, np.int16)
            pdo = np.zeros(0, np.uint8)
        series = []
        for (n, p, cob, names, bus), parts in sorted(
            self._blocks.items(), key=lambda kv: kv[0][:3]
        ):
            blk = parts[0][2]
            series.append(
                SignalSeries(
                    node=n,
                    pdo=p,
                    cob_id=cob,
                    t=np.concatenate([x[0] for x in parts]),
                    rows=np.concatenate([x[1] for x in parts]),
                    columns={k: np.concatenate([x[2].columns[k] for x in parts]) for k in names},
                    units=dict(blk.units),
                    bus=bus if self._several_signals else None,
                    objects={k: v for x in parts for k, v in x[2].objects.items()},
                )
            )
        self.states.sort(key=lambda e: e.t)
        return (cls or Capture)(
            self.source,
            fb,
            service,
            node,
            pdo,
            series,
            self.records,
            self.events,
            self.states,
            problems,
            network,
            profiles or {},
            drive_changes=self.drive,
            record_bus=self.record_bus,
            sync_late=sync,
        )


class CaptureSink(Sink):
    """`load()`'s sink: every batch kept as columns, one Capture at the end."""

    needs_events = True

    def __init__(self, cls: type[Capture] | None = None) -> None:
        self.cls = cls  # the Capture class to build (load() gives the API's, with assert_*)

    def open(self, run) -> None:
        super().open(run)
        self.collector = Collector(run.name)
        self.capture: Capture | None = None

    def write(self, batch: DecodedBatch) -> None:
        self.collector.add(batch)

    def close(self) -> None:
        from cananalyze.decode.node_tally import bus_profiles, node_profiles

        run = self.run
        self.capture = self.collector.capture(
            run.problems, str(run.options.network or ""), node_profiles(run.network), self.cls
        )
        self.capture.bus_profiles = bus_profiles(run.decoder)
        self.capture.checker = run.checker
        self.capture.options = run.options
        from cananalyze.decode.commissioning import Commissioning

        self.capture.commissioning = run.decoder.processors_of(Commissioning)
