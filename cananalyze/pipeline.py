"""The one pipeline: options, a source, a decoder and the sinks, joined by one loop.

Every door goes through here: `decode`, `check`, `export`, `live`, `load()` and
the pytest assertions each turn what they were given into `Options`, open a
source, build the decoder and call `run` with their sinks. So no two outputs can
disagree about what a log holds: they read the same decoded batches.

    opts = Options(network="net.toml", rules="rules.yaml")
    source = open_source("run.blf", opts)
    run(source, build_decoder(opts), [TableSink("out", "parquet")], opts)
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from cananalyze.errors import ProblemLog, UsageError
from cananalyze.frames import MAX_BUSES, MAX_CHANNELS, OTHER_CHANNELS, FrameBatch
from cananalyze.protocol.cobid import CobClassifier
from cananalyze.records import DecodedBatch
from cananalyze.runtime import signals

if TYPE_CHECKING:
    from cananalyze.checks.engine import Checker
    from cananalyze.network.model import NetworkModel
    from cananalyze.network.spec import NetworkSpec
    from cananalyze.outputs.sink import Sink

TIME_MODES = ("rel", "abs")


@dataclass
class Options:
    """What a run is asked to do, whichever door it came through (CLI, `load()`, fleet).

    Devices: `devices` maps node-IDs to built-in profile keys, `eds` to EDS/DCF files,
    on top of the `network` file. `rules` adds the rules file's assertions to the
    CANopen rules, which run when `checks` is set (or a rules file is given).
    Filters (`nodes`, `services`, `t_from`/`t_to` in seconds after the log's first
    frame) choose what the sinks see; the decoder and the rules always see everything.
    `time`: text outputs show seconds from the first frame ("rel") or as logged ("abs").
    """

    network: str | Path | None = None
    devices: Mapping[int, str] = field(default_factory=dict)
    eds: Mapping[int, str | Path] = field(default_factory=dict)
    rules: str | Path | None = None
    checks: bool = False
    timing: bool = False
    sdo_timeout: float = 1.0
    strict: bool = False
    input_format: str | None = None
    bitrate: int | None = None
    nodes: frozenset[int] | None = None
    services: frozenset[int] | None = None
    t_from: float | None = None
    t_to: float | None = None
    time: str = "rel"
    dbc: tuple[str | Path, ...] = ()  # DBC files: their messages decoded as signals (--dbc)

    def __post_init__(self) -> None:
        if isinstance(self.dbc, (str, Path)):
            self.dbc = (self.dbc,)
        self.dbc = tuple(self.dbc or ())
        for what, table in (("--device", self.devices), ("--eds", self.eds)):
            for node in table:
                if not isinstance(node, int) or isinstance(node, bool) or not 1 <= node <= 127:
                    raise UsageError(f"{what} takes NODE=VALUE with NODE 1..127 (got {node!r})")
        if self.time not in TIME_MODES:
            raise UsageError(f"--time is rel or abs (got {self.time!r})")
        if self.sdo_timeout is not None and not self.sdo_timeout > 0:
            raise UsageError(f"--sdo-timeout must be positive (got {self.sdo_timeout})")
        if self.bitrate is not None and not 0 < self.bitrate <= 8_000_000:
            raise UsageError(f"--bitrate must be 1..8000000 bit/s (got {self.bitrate})")

    @property
    def checking(self) -> bool:
        return self.checks or self.rules is not None

    @property
    def filtered(self) -> bool:
        return (
            self.nodes is not None
            or self.services is not None
            or self.t_from is not None
            or self.t_to is not None
        )


# --- the decoder ---------------------------------------------------------------------


class Processor(Protocol):
    def process(self, batch: DecodedBatch) -> None:
        """Add notes, records or signals to the batch; keep state for the next one."""

    def finish(self, batch: DecodedBatch) -> None:
        """End of log: emit what is still pending into `batch` (an empty batch)."""


class Decoder:
    """FrameBatches in, DecodedBatches out: the columnar classifier, then each processor.

    Live sniffing feeds small batches to the same object, so both give the same records.

    Several buses (a log or `live -c` with frames of more than one channel): node 5 on
    can0 and node 5 on can1 are two devices, so each channel gets a decoder of its own
    (classifier, SDO tracker, network model, PDO/EMCY/drive decoders, checker), made by
    `spawn` when the channel is first seen; this one follows the first channel. A batch
    of several channels is split by channel and the decoded parts merged back in row
    order. A log of one channel takes the one-decoder path, no copy.
    """

    def __init__(self, processors: list[Processor] | None = None) -> None:
        self.classifier = CobClassifier()
        self.processors: list[Processor] = list(processors or [])
        self.network: NetworkModel | None = None
        self.checker: Checker | None = None  # rules and timing statistics, when asked
        self.spawn: Callable[[], Decoder] | None = None  # a fresh decoder for another bus
        self.bus: str | None = None  # this decoder's channel name, once several are seen
        self._channel: int | None = None  # channel index of the frames seen so far
        self.buses: dict[int, Decoder] | None = None  # channel -> its decoder (several)
        self._decoders: list[Decoder] = []  # each bus's decoder once, this one first
        self._slot: np.ndarray | None = None
        self._other: int | None = None  # the decoder the channels past MAX_BUSES share

    def decode(self, batch: FrameBatch) -> DecodedBatch:
        if self.spawn is not None and len(batch):
            ch = batch.channel
            if self.buses is None:
                if self._channel is None:
                    self._channel = int(ch[0])
                if not (ch != self._channel).any():
                    return self._decode_one(batch)
                self._several(batch)
            return self._decode_buses(batch)
        return self._decode_one(batch)

    def _decode_one(self, batch: FrameBatch) -> DecodedBatch:
        c = self.classifier.classify(batch)
        out = DecodedBatch(batch, c.service, c.node, c.pdo, bus=self.bus)
        for p in self.processors:
            p.process(out)
        return out

    def _several(self, batch: FrameBatch) -> None:
        """A second channel: from now on, one decoder per channel (this one the first's)."""
        self.buses = {self._channel: self}
        self._decoders = [self]
        self._slot = np.full(MAX_CHANNELS, -1, np.int32)  # channel -> index in _decoders
        self._slot[self._channel] = 0
        self._name(self, batch.channel_label(self._channel))

    def _bus(self, c: int, batch: FrameBatch) -> int:
        """The index of channel c's decoder, made on first sight; past MAX_BUSES, the
        channels left share one (a hostile log naming thousands of channels)."""
        k = int(self._slot[c])
        if k >= 0:
            return k
        shared = len(self._decoders) >= MAX_BUSES - 1  # the last one: the shared one
        if shared and self._other is not None:
            k = self._other
        else:
            dec = self.spawn()
            self._name(dec, OTHER_CHANNELS if shared else batch.channel_label(c))
            if dec.checker is not None and self.checker is not None:
                dec.checker.t0 = self.checker.t0  # times from the log's first frame
                dec.checker.first_bus = False
                self.checker.others.append(dec.checker)  # its findings are the run's
            k = len(self._decoders)
            self._decoders.append(dec)
            if shared:
                self._other = k
        self._slot[c] = k
        self.buses[c] = self._decoders[k]
        return k

    def of_bus(self, name: str | None) -> Decoder:
        """The decoder of the bus named `name` (this one when there is one bus, or no
        decoder has that name): its network model and checker are that bus's."""
        for dec in self._decoders:
            if dec.bus == name:
                return dec
        return self

    def networks(self) -> dict[str | None, NetworkModel | None]:
        """Each bus's network model by bus name ({None: the one} on a log of one bus): a
        device identified by its 0x1018 read on can1 is in can1's model only."""
        if self.buses is None:
            return {None: self.network}
        return {dec.bus: dec.network for dec in self._decoders}

    @staticmethod
    def _name(dec: Decoder, name: str) -> None:
        dec.bus = name
        if dec.checker is not None:
            dec.checker.name_bus(name)

    def _decode_buses(self, batch: FrameBatch) -> DecodedBatch:
        ch = batch.channel
        if self.checker is not None and self.checker.t0 is None:
            for dec in self._decoders:  # the log's first frame, whichever bus
                if dec.checker is not None:
                    dec.checker.t0 = float(batch.t[0])
        for c in np.flatnonzero(np.bincount(ch, minlength=1)).tolist():
            if self._slot[c] < 0:
                self._bus(c, batch)
        slot = self._slot[ch]
        first = int(slot[0])
        if not (slot != first).any():
            return self._decoders[first]._decode_one(batch)
        order = np.argsort(slot, kind="stable")
        cut = np.flatnonzero(np.diff(slot[order])) + 1
        parts = []
        for rows in np.split(order, cut):
            dec = self._decoders[int(slot[rows[0]])]
            parts.append((rows, dec._decode_one(batch.take(rows))))
        names = np.array([None] + [d.bus for d in self._decoders], object)
        return merge_buses(batch, parts, names[self._slot + 1])

    def tick(self, now: float) -> DecodedBatch | None:
        """Live, between frames: a zero-row batch with what time alone completes at `now`
        (the log's clock): SDO requests unanswered past the timeout, the findings the
        deadline rules report as overdue. None when there is nothing.

        A processor with `tick(batch, now)` is asked that (the SDO tracker, the checks);
        the others see the zero-row batch as a batch (the network model reads the SDO
        records the tick completed)."""
        if self.buses is None:
            return self._tick_one(now)
        done = [out for dec in self._decoders if (out := dec._tick_one(now)) is not None]
        if not done:
            return None
        return merge_ends(done)

    def _tick_one(self, now: float) -> DecodedBatch | None:
        fb = FrameBatch.empty()
        c = self.classifier.classify(fb)
        out = DecodedBatch(fb, c.service, c.node, c.pdo, bus=self.bus)
        for p in self.processors:
            tick = getattr(p, "tick", None)
            if tick is not None:
                tick(out, now)
            else:
                p.process(out)
        return out if out.records or out.findings else None

    def finish(self) -> DecodedBatch:
        """A zero-row batch carrying the records that only the end of the log completes."""
        if self.buses is None:
            return self._finish_one()
        decoders = self._decoders
        checkers = [d.checker for d in decoders if d.checker is not None]
        if len(checkers) > 1:
            from cananalyze.checks.engine import whole_log

            whole_log(checkers)
            # the log ends at its last frame whichever bus it was on: a node silent
            # since is judged against that end, as on a log of one bus
            ends = [c.t_last for c in checkers if c.t_last is not None]
            for c in checkers:
                c.t_last = max(ends) if ends else None
        return merge_ends([d._finish_one() for d in decoders])

    def _finish_one(self) -> DecodedBatch:
        empty = self.decode(FrameBatch.empty())  # (no frame: this decoder's own path)
        for p in self.processors:
            p.finish(empty)
        return empty


def merge_buses(
    batch: FrameBatch,
    parts: list[tuple[np.ndarray, DecodedBatch]],
    channel_bus: np.ndarray | None = None,
) -> DecodedBatch:
    """One DecodedBatch of `batch` from its channels' decoded parts ((rows, part) each):
    columns scattered back to their rows, records and findings at their rows, in row order
    (a record at its part's end stays at the batch's end). `channel_bus`: the bus name of
    each channel index (a frame row's bus is its channel's)."""
    n = len(batch)
    service = np.zeros(n, np.uint8)
    node = np.full(n, -1, np.int16)
    pdo = np.zeros(n, np.uint8)
    out = DecodedBatch(batch, service, node, pdo)
    out.channel_bus = channel_bus
    founds = []
    for rows, part in parts:
        at = np.append(rows, n)  # a part's row len(part): the batch's end
        service[rows] = part.service
        node[rows] = part.node
        pdo[rows] = part.pdo
        out.notes = _merge_notes(out.notes, rows, part.notes)
        for sb in part.signals:
            sb.rows = rows[sb.rows]
            out.signals.append(sb)
        out.row_notes.extend((rows[r], note) for r, note in part.row_notes)
        out.drive.extend(c._replace(row=int(at[c.row]), bus=part.bus) for c in part.drive)
        if len(part.findings):
            f = part.findings
            f.row = at[np.clip(f.row, 0, len(rows))]
            founds.append(f)
    out.records, of_part = _merge_records([(np.append(rows, n), part) for rows, part in parts])
    out.record_bus = _bus_names([part.bus for _, part in parts], of_part)
    out.drive.sort(key=lambda c: c.row)
    if founds:
        from cananalyze.checks.columns import FindingColumns

        out.findings = FindingColumns.concat(founds).sort()
    return out


def _merge_notes(merged: dict, rows: np.ndarray, notes: dict) -> dict:
    """A part's notes at the batch's rows; the SDO notes a part has not written yet
    (`LazyNotes`: only text outputs read them) stay unwritten until the batch's are read."""
    from cananalyze.sdo.lazynotes import LazyNotes

    pending = notes.pending_rows() if isinstance(notes, LazyNotes) else None
    if pending is None:
        dict.update(merged, {int(rows[r]): v for r, v in notes.items()})
        return merged
    dict.update(merged, {int(rows[r]): v for r, v in dict.items(notes)})

    def fill(into: dict) -> None:
        for r, v in notes.items():  # the part's pending notes written, then mapped
            LazyNotes.write(into, int(rows[r]), v)

    if isinstance(merged, LazyNotes):
        merged.defer(fill, rows[pending])
        return merged
    return LazyNotes(merged, fill, rows[pending])


def merge_ends(parts: list[DecodedBatch]) -> DecodedBatch:
    """The zero-row batches of several buses (live ticks, the end of the log) as one."""
    if len(parts) == 1:
        return parts[0]
    from cananalyze.checks.columns import FindingColumns

    out = parts[0]
    out.records = [r for p in parts for r in p.records]
    of_part = np.repeat(np.arange(len(parts)), [len(p.records) for p in parts])
    out.record_bus = _bus_names([p.bus for p in parts], of_part)
    out.bus = None
    out.drive = [c._replace(bus=p.bus) for p in parts for c in p.drive]
    out.findings = FindingColumns.concat([p.findings for p in parts]).sort()
    return out


def _merge_records(parts: list[tuple[np.ndarray, DecodedBatch]]) -> tuple[list, np.ndarray]:
    """The parts' records at the batch's rows ((row map, part) each), in row order, and
    the part each came from. The
    SDO fast path's records a part has not built stay unbuilt, with their columns
    (`sdo_fast`: the checks and the summary read those); the rest are read as they are."""
    from cananalyze.records import SdoColumns
    from cananalyze.sdo.lazyrecords import LazyRecords

    get = list.__getitem__
    rows, keys, lazy, fasts = [], [], [], []
    for p, (at, part) in enumerate(parts):
        recs, fast = part.records, part.sdo_fast
        m = len(recs)
        row = np.zeros(m, np.int64)
        is_fast = np.zeros(m, bool)
        if fast is not None and fast.slots.size and m > int(fast.slots[-1]):
            is_fast[fast.slots] = True
            row[fast.slots] = fast.row
            fasts.append((p, at, fast))
        others = np.flatnonzero(~is_fast)
        row[others] = [get(recs, k)[0] for k in others.tolist()]
        rows.append(at[np.clip(row, 0, at.size - 1)])
        keys.append(np.stack((np.full(m, p), np.arange(m)), 1))
        lazy.append(is_fast)
    if not rows:
        return [], np.zeros(0, np.int64)
    row = np.concatenate(rows)
    key = np.concatenate(keys)
    deferred = np.concatenate(lazy)
    order = np.argsort(row, kind="stable")
    merged = [
        (r, None if d else get(parts[p][1].records, k)[1])
        for r, d, (p, k) in zip(
            row[order].tolist(), deferred[order].tolist(), key[order].tolist(), strict=True
        )
    ]
    of_part = key[order][:, 0]
    if not fasts:
        return merged, of_part
    slots = np.flatnonzero(deferred[order])  # merged positions of the unbuilt ones
    where = key[order][slots]  # (part, slot in the part) of each

    def build(js: np.ndarray | None) -> list[dict]:
        picks = where if js is None else where[js]
        if js is None:
            for p in set(picks[:, 0].tolist()):
                list(parts[p][1].records)  # the part's records built at once
        return [parts[p][1].records[k][1] for p, k in picks.tolist()]

    pos = np.empty(order.size, np.int64)  # merged position of each (part, slot)
    pos[order] = np.arange(order.size)
    start = np.cumsum([0] + [len(part.records) for _, part in parts])
    cols = {f: [] for f in ("slots", "row", "req_row", "node", "upload", "index")}
    cols.update({f: [] for f in ("subindex", "ok", "latency")})
    for p, at, fast in fasts:
        cols["slots"].append(pos[start[p] + fast.slots])
        cols["row"].append(at[fast.row])
        cols["req_row"].append(at[np.clip(fast.req_row, 0, at.size - 1)])
        for f in ("node", "upload", "index", "subindex", "ok", "latency"):
            cols[f].append(getattr(fast, f))
    columns = {f: np.concatenate(v) for f, v in cols.items()}
    by_slot = np.argsort(columns["slots"], kind="stable")
    out = LazyRecords(merged)
    out.defer(
        slots,
        row[order][slots].tolist(),
        build,
        SdoColumns(**{f: v[by_slot] for f, v in columns.items()}),
    )
    return out, of_part


def _bus_names(names: list[str | None], of_part: np.ndarray) -> np.ndarray:
    """Each merged record's bus: the name of the part it came from."""
    table = np.empty(len(names), object)
    table[:] = names
    return table[of_part]


def network_spec(opts: Options) -> NetworkSpec:
    """The user's declarations, later sources winning key by key: the network file, then
    the rules file's `network:` section (the more specific document: one test's
    expectations of one installation), then --device/--eds (a node's device named last,
    on the command line). docs/network-file.md, "Combining sources"."""
    from cananalyze.network.netfile import combine, read_network_file

    sources = []
    if opts.network:
        sources.append(read_network_file(opts.network))
    if opts.rules:
        from cananalyze.checks.rulesfile import rules_network

        section = rules_network(opts.rules)
        if section is not None:
            sources.append(section)
    spec = combine(*sources, source=str(opts.network) if opts.network else None)
    if opts.devices or opts.eds:
        from cananalyze.network.profile import load_builtin, load_eds

        for node, name in opts.devices.items():
            ns = spec.node(node)
            key = str(name).lower().replace("-", "").replace(" ", "")
            ns.profile, ns.how = load_builtin(key), "user --device"
        for node, file in opts.eds.items():
            ns = spec.node(node)
            ns.profile, ns.how = load_eds(file, node), "user --eds"
    return spec


def build_decoder(
    opts: Options | None = None, checker: Checker | None = None, keep_findings: bool = True
) -> Decoder:
    """The decoder the options describe. Processor order matters: SDO transactions first
    (the network model reads them), the PDO and EMCY decoders after the model, the
    checks last (they read everything the others found).

    `checker`: one built earlier (so a bad rules file fails before the log is opened);
    otherwise built here when the options ask for checks or timing statistics (keeping
    its findings unless `keep_findings=False`: see `build_checker`).
    """
    from cananalyze.network.drive_tracker import DriveTracker
    from cananalyze.network.emcy_notes import EmcyDecoder
    from cananalyze.network.model import NetworkModel
    from cananalyze.network.pdo_processor import PdoDecoder
    from cananalyze.sdo.processor import SdoProcessor
    from cananalyze.sdo.tracker import SdoTracker

    opts = opts or Options()
    dbc = None
    if opts.dbc:
        from cananalyze.network.dbc import load_dbc

        dbc = load_dbc(opts.dbc)  # a bad DBC fails before the log is opened
    spec = network_spec(opts)
    if dbc:  # the DBC's identifiers belong on the bus (the unknown-identifier rule)
        spec.known_cob_ids |= {i for i, _ in dbc.messages}
    model = NetworkModel(spec)
    tracker = SdoTracker(timeout=opts.sdo_timeout, object_info=model.object_info)
    for node, request, response in model.sdo_channels:
        tracker.add_channel(node, request, response)
    skip = dbc.standard_ids if dbc else set()  # the DBC's layout wins over the profile's
    processors = [SdoProcessor(tracker), model, PdoDecoder(model, skip), EmcyDecoder(model)]
    if dbc:
        from cananalyze.network.dbc_processor import DbcDecoder

        processors.insert(3, DbcDecoder(dbc))
    decoder = Decoder([*processors, DriveTracker(model)])
    model.attach(decoder)
    decoder.network = model
    if checker is None and (opts.checking or opts.timing):
        checker = build_checker(opts, keep_findings)
    if checker is not None:
        from cananalyze.checks.model_config import ModelConfig

        checker.config = ModelConfig(model)  # the model holds every declaration and the log
        decoder.processors.append(checker)
        decoder.checker = checker
    decoder.spawn = _spawner(opts, checker)
    return decoder


def _spawner(opts: Options, checker: Checker | None) -> Callable[[], Decoder]:
    """Another bus's decoder: the same declarations, its own state (its checker a fresh
    copy of `checker`'s rules, taken now, before any frame)."""
    rules = None if checker is None else checker.pristine()

    def spawn() -> Decoder:
        fresh = None
        if rules is not None:
            fresh = rules()
        dec = build_decoder(opts, fresh)
        dec.spawn = None
        return dec

    return spawn


def build_checker(opts: Options, keep_findings: bool = True) -> Checker:
    """The rules the options ask for: the CANopen rules and the rules file's assertions
    when checking, none (timing statistics only) otherwise.

    `keep_findings=False` for a run whose sinks take every finding from the batches
    (export, fleet): the checker then holds none to the end of the log."""
    from cananalyze.checks.build import build_checker as from_files
    from cananalyze.checks.engine import Checker

    checker = from_files(opts.rules) if opts.checking else Checker(rules=[])
    checker.keep_findings = keep_findings
    # the gap statistics only for a report that prints them (--timing, --summary)
    checker.timing.with_stats = opts.timing
    return checker


# --- sources -------------------------------------------------------------------------


class Source(Protocol):
    """Where frames come from: a log file, stdin or a live bus."""

    path: str
    problems: ProblemLog

    def batches(self) -> Iterator[FrameBatch]: ...


class MemorySource:
    """Frames already in memory (tests, the simulator, pytest assertions) as a Source."""

    def __init__(self, batches: FrameBatch | Iterable[FrameBatch], path: str = "<frames>") -> None:
        self._batches = [batches] if isinstance(batches, FrameBatch) else list(batches)
        self.path = path
        self.problems = ProblemLog()

    def batches(self) -> Iterator[FrameBatch]:
        yield from self._batches


def open_source(log: str | Path | object, opts: Options | None = None) -> Source:
    """A log path (or "-" for stdin) opened for batch reading, or a python-can bus.

    Raises InputError with a one-line reason for a file it cannot read.
    """
    opts = opts or Options()
    if isinstance(log, (str, Path)):
        from cananalyze.io.source import open_log

        return open_log(log, strict=opts.strict, fmt=opts.input_format)
    if isinstance(log, FrameBatch):
        return MemorySource(log)
    from cananalyze.io.live import LiveSource

    return LiveSource(log)


# --- the loop ------------------------------------------------------------------------


@dataclass
class Run:
    """What the sinks may ask about the run in progress."""

    options: Options
    source: Source
    decoder: Decoder
    t0: float | None = None  # time of the log's first frame (text times count from it)
    frames: int = 0  # frames read
    shown: int = 0  # frames that passed the filters
    rows: int = 0  # rows written to the sinks so far (row numbers of events)
    stopped: bool = False  # a live run ended by the user or its duration
    t_last: float | None = None
    # frames per node (index node + 1, 0 = no node), counted when filtering: what to
    # tell a user whose --node matched nothing
    node_frames: np.ndarray = field(default_factory=lambda: np.zeros(129, np.int64))

    @property
    def problems(self) -> ProblemLog:
        return self.source.problems

    @property
    def network(self) -> NetworkModel | None:
        return self.decoder.network

    @property
    def checker(self) -> Checker | None:
        return self.decoder.checker

    @property
    def name(self) -> str:
        return str(self.source.path)


class _Filter:
    """The options' node/service/time filters as a row mask and a record test."""

    def __init__(self, opts: Options) -> None:
        self.opts = opts
        self.nodes = None if opts.nodes is None else np.array(sorted(opts.nodes), np.int16)
        self.services = None if opts.services is None else np.array(sorted(opts.services), np.uint8)
        from cananalyze.protocol.services import SERVICE_NAMES

        labels = {SERVICE_NAMES[s] for s in opts.services or ()}
        # records pass the service filter when their own services are asked for
        self.record_services = {
            "sdo": bool(labels & {"sdo_request", "sdo_response"}),
            "signal": bool(labels & {"tpdo", "rpdo"}),
        }

    def mask(self, batch: DecodedBatch, t0: float) -> np.ndarray:
        fb = batch.frames
        keep = np.ones(len(fb), bool)
        if self.nodes is not None:
            keep &= np.isin(batch.node, self.nodes)
        if self.services is not None:
            keep &= np.isin(batch.service, self.services)
        if self.opts.t_from is not None:
            keep &= fb.t - t0 >= self.opts.t_from
        if self.opts.t_to is not None:
            keep &= fb.t - t0 <= self.opts.t_to
        return keep

    def record(self, rec: dict, t0: float) -> bool:
        """Records obey the same filters as frames (findings pass the service filter)."""
        o = self.opts
        if o.nodes is not None and rec.get("node") not in o.nodes:
            return False
        if o.services is not None and not self.record_services.get(rec.get("kind"), True):
            return False
        t = rec.get("t")
        if t is not None and o.t_from is not None and t - t0 < o.t_from:
            return False
        return not (t is not None and o.t_to is not None and t - t0 > o.t_to)


def run(
    source: Source,
    decoder: Decoder,
    sinks: Iterable[Sink],
    opts: Options | None = None,
    *,
    stop: Callable[[], bool] | None = None,
    tick: float | None = None,
) -> Run:
    """Decode every batch of `source` into every sink; returns the finished Run.

    Sinks are opened before the first frame is read and closed after the last (the
    decoder's end-of-log batch included); if anything fails or the user interrupts,
    every sink is aborted instead and the error goes on. `stop()` is asked after each
    batch (live runs: duration, Ctrl-C); `tick` seconds of wall clock apart, live
    sinks get `tick(now)`. Live (`tick` set), the decoder is asked after every batch
    (a live source also yields empty ones while the bus is quiet) what time alone has
    completed at the bus's clock now: the latest frame's time plus the wall time since
    its batch arrived. A node silent while others talk is reported as soon as it is
    overdue, and so is one on a bus where no frame comes at all (its finding says so:
    the adapter or the logger may be what stopped), as are SDO requests left
    unanswered. A file is judged by its frames alone: its end is no silence.
    """
    from cananalyze.events.build import EventBuilder

    opts = opts or Options()
    sinks = list(sinks)
    state = Run(opts, source, decoder)
    filt = _Filter(opts) if opts.filtered else None
    events = EventBuilder() if any(s.needs_events for s in sinks) else None
    opened: list[Sink] = []
    ended: list[BaseException] = []  # a live source's failure: outputs kept, then raised
    try:
        for sink in sinks:
            with named_errors(sink):
                sink.open(state)
            opened.append(sink)
        next_tick = time.monotonic() + tick if tick else None
        arrived_last: float | None = None  # wall clock when the latest frame's batch came
        batches = _read_ahead(source, ended)
        try:
            for fb in batches:
                arrived = time.monotonic()
                _deliver(state, decoder.decode(fb), sinks, filt, events)
                if next_tick is not None:
                    if len(fb):
                        arrived_last = arrived
                    if state.t_last is not None and arrived_last is not None:
                        # the bus's clock now; a batch that came empty had no frame waiting,
                        # so no frame still to come is older than this
                        late = decoder.tick(state.t_last + (arrived - arrived_last))
                        if late is not None:
                            _deliver(state, late, sinks, filt, events)
                    now = time.monotonic()
                    if now >= next_tick:
                        for sink in sinks:
                            with named_errors(sink):
                                sink.tick(now)
                        next_tick = now + tick
                if stop is not None and stop():
                    state.stopped = True
                    _stop(source)
        finally:
            close = getattr(batches, "close", None)
            if close is not None:
                close()  # the reader thread stops before the problems are reported
        _deliver(state, decoder.finish(), sinks, filt, events)
        for sink in sinks:  # a sink of its own making without finish/commit: close()
            with named_errors(sink):
                (getattr(sink, "finish", None) or sink.close)()
        with signals.held():  # only when every output is complete: all or nothing
            for sink in sinks:
                with named_errors(sink):
                    getattr(sink, "commit", lambda: None)()
    except BaseException:
        for sink in opened:
            with contextlib.suppress(Exception):  # the first error is the one to report
                sink.abort()
        raise
    if ended:
        raise ended[0]
    return state


def unmatched_filter(state: Run) -> str | None:
    """A warning when the filters matched no frame of a log that had some, else None."""
    opts = state.options
    if not opts.filtered or state.shown or not state.frames:
        return None
    asked = []
    if opts.nodes is not None:
        asked.append("--node " + ",".join(map(str, sorted(opts.nodes))))
    if opts.services is not None:
        from cananalyze.protocol.services import SERVICE_NAMES

        asked.append("--service " + ",".join(SERVICE_NAMES[s] for s in sorted(opts.services)))
    if opts.t_from is not None:
        asked.append(f"--from {opts.t_from:g}")
    if opts.t_to is not None:
        asked.append(f"--to {opts.t_to:g}")
    seen = [str(n) for n in np.flatnonzero(state.node_frames[1:]).tolist()]
    nodes = f"nodes {', '.join(seen)}" if seen else "no node-IDs"
    span = (state.t_last or 0.0) - (state.t0 or 0.0)
    return (
        f"{' '.join(asked)} matched none of the {state.frames:,} frames of {state.name} "
        f"(it has {nodes}, over {span:.3f} s)"
    )


def _read_ahead(source: Source, ended: list) -> Iterator[FrameBatch]:
    """A file is parsed on the other core while this one decodes; a live bus is not
    (its reader thread already runs beside the loop). A live interface that fails ends
    the run like a stop: what was decoded is written, then the error is raised."""
    from cananalyze.io.live import LiveSource

    if isinstance(source, LiveSource):
        return _until_failure(source.batches(), ended)
    from cananalyze.io.prefetch import prefetch

    return prefetch(source.batches())


def _until_failure(batches: Iterator[FrameBatch], ended: list) -> Iterator[FrameBatch]:
    from cananalyze.io.live import LiveError, LiveOpenError

    try:
        yield from batches
    except LiveOpenError:
        raise  # nothing was read: the outputs are dropped
    except LiveError as exc:
        ended.append(exc)


def _stop(source: Source) -> None:
    stop = getattr(source, "stop", None)
    if stop is not None:
        stop()


def _deliver(state: Run, batch: DecodedBatch, sinks: list[Sink], filt, events) -> None:
    fb = batch.frames
    if len(fb):
        if state.t0 is None:
            state.t0 = float(fb.t[0])
        state.t_last = float(fb.t[-1])
    state.frames += len(fb)
    if filt is not None:
        node = batch.node[(batch.node >= -1) & (batch.node < 128)].astype(np.intp) + 1
        state.node_frames += np.bincount(node, minlength=129)
        t0 = state.t0 if state.t0 is not None else 0.0
        batch = batch.select(filt.mask(batch, t0), lambda rec: filt.record(rec, t0))
    state.shown += len(batch)
    if events is not None:
        batch.events, batch.states = events.build(batch, state.rows)
    for sink in sinks:
        with named_errors(sink):
            sink.write(batch)
    state.rows += len(batch)


@contextlib.contextmanager
def named_errors(sink: Sink) -> Iterator[None]:
    """An OSError from a sink names its output (a writer thread's "No space left on
    device" would otherwise reach the user without saying which file)."""
    try:
        yield
    except OSError as exc:
        dest = getattr(sink, "dest", None)
        if exc.filename or not dest:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), dest) from exc
