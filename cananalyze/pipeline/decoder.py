"""The decoder: the columnar classifier, then each stateful processor, one per bus; and the builders that make it from Options."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Protocol

import numpy as np

from cananalyze.core.frames import MAX_BUSES, MAX_CHANNELS, OTHER_CHANNELS, FrameBatch
from cananalyze.core.records import DecodedBatch
from cananalyze.core.sdo_records import SdoRecords
from cananalyze.core.text import printable
from cananalyze.protocol.cobid import CobClassifier

if TYPE_CHECKING:
    from cananalyze.checks.engine import Checker
    from cananalyze.config.spec import NetworkSpec
    from cananalyze.decode.model import NetworkModel

from cananalyze.pipeline.options import Options


class Processor(Protocol):
    def process(self, batch: DecodedBatch) -> None:
        """Add notes, records or signals to the batch; keep state for the next one."""

    def finish(self, batch: DecodedBatch) -> None:
        """End of log: emit what is still pending into `batch` (an empty batch)."""


@functools.lru_cache(maxsize=64)
def _printable_channels(channels: tuple[str, ...]) -> tuple[str, ...]:
    """The interfaces' names as a terminal may show them (`core.text.printable`): a log's
    channel column is the log writer's text. Every frame of every source passes here."""
    return tuple(printable(c) for c in channels)


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
        batch.channels = _printable_channels(batch.channels)
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

    def processors_of(self, kind: type) -> list[tuple[str | None, Processor]]:
        """(bus name, processor) of every bus's processors of type `kind` (bus None on a
        log of one bus): what a sink reads of a producer at the end of the run."""
        return [
            (dec.bus, p)
            for dec in self._decoders or [self]
            for p in dec.processors
            if isinstance(p, kind)
        ]

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
        if part.sync_latency is not None:
            if out.sync_latency is None:
                out.sync_latency = np.full(n, np.nan)
            out.sync_latency[rows] = part.sync_latency
        out.drive.extend(c._replace(row=int(at[c.row]), bus=part.bus) for c in part.drive)
        out.commissioning.extend(
            c._replace(row=None if c.row is None else int(at[c.row]), bus=part.bus)
            for c in part.commissioning
        )
        if len(part.findings):
            f = part.findings
            f.row = at[np.clip(f.row, 0, len(rows))]
            founds.append(f)
    out.records, of_part = SdoRecords.merge([(np.append(rows, n), p.records) for rows, p in parts])
    out.record_bus = _bus_names([part.bus for _, part in parts], of_part)
    out.drive.sort(key=lambda c: c.row)
    if founds:
        from cananalyze.core.finding_columns import FindingColumns

        out.findings = FindingColumns.concat(founds).sort()
    return out


def _merge_notes(merged: dict, rows: np.ndarray, notes: dict) -> dict:
    """A part's notes at the batch's rows; the SDO notes a part has not written yet
    (`LazyNotes`: only text outputs read them) stay unwritten until the batch's are read."""
    from cananalyze.decode.sdo.lazynotes import LazyNotes

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
    from cananalyze.core.finding_columns import FindingColumns

    out = parts[0]  # its own records, bus and items are read below before it is overwritten
    of_part = np.repeat(np.arange(len(parts)), [len(p.records) for p in parts])
    out.records = SdoRecords([r for p in parts for r in p.records])
    out.record_bus = _bus_names([p.bus for p in parts], of_part)
    out.drive = [c._replace(bus=p.bus) for p in parts for c in p.drive]
    out.commissioning = [c._replace(bus=p.bus) for p in parts for c in p.commissioning]
    out.findings = FindingColumns.concat([p.findings for p in parts]).sort()
    out.bus = None  # last: `out` is the first bus's part, whose name its items take above
    return out


def _bus_names(names: list[str | None], of_part: np.ndarray) -> np.ndarray:
    """Each merged record's bus: the name of the part it came from."""
    table = np.empty(len(names), object)
    table[:] = names
    return table[of_part]


def network_spec(opts: Options, checker: Checker | None = None) -> NetworkSpec:
    """The user's declarations, later sources winning key by key: the network file, then
    the rules file's `network:` section (the more specific document: one test's
    expectations of one installation), then --device/--eds (a node's device named last,
    on the command line). docs/network-file.md, "Combining sources".

    The section is the one `checker` read with its rules from the same file, if given:
    the rules file is parsed once per run."""
    from cananalyze.config.netfile import combine, read_network_file

    sources = []
    if opts.network:
        sources.append(read_network_file(opts.network))
    if opts.rules:
        section = _rules_section(opts, checker)
        if section is not None:
            sources.append(section)
    spec = combine(*sources, source=str(opts.network) if opts.network else None)
    if opts.devices or opts.eds:
        from cananalyze.devices.builtin import load_builtin
        from cananalyze.devices.profile import load_eds

        for node, name in opts.devices.items():
            ns = spec.node(node)
            key = str(name).lower().replace("-", "").replace(" ", "")
            ns.profile, ns.how = load_builtin(key), "user --device"
        for node, file in opts.eds.items():
            ns = spec.node(node)
            ns.profile, ns.how = load_eds(file, node), "user --eds"
    return spec


def _rules_section(opts: Options, checker: Checker | None) -> dict | None:
    """The rules file's `network:` settings: as the checker read them with its rules, or
    read here (no checker, or one whose rules came from elsewhere)."""
    known = getattr(checker, "rules_file", None)
    if known is not None and known[0] == str(opts.rules):
        return known[1]
    from cananalyze.checks.rulesfile import rules_network

    return rules_network(opts.rules)


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
    from cananalyze.decode.drive_tracker import DriveTracker
    from cananalyze.decode.emcy_notes import EmcyDecoder
    from cananalyze.decode.model import NetworkModel
    from cananalyze.decode.pdo_processor import PdoDecoder
    from cananalyze.decode.sdo.processor import SdoProcessor
    from cananalyze.decode.sdo.tracker import SdoTracker
    from cananalyze.decode.srdo_processor import SrdoDecoder

    opts = opts or Options()
    dbc = None
    if opts.dbc:
        from cananalyze.devices.dbc import load_dbc

        dbc = load_dbc(opts.dbc)  # a bad DBC fails before the log is opened
    if checker is None and (opts.checking or opts.timing):
        checker = build_checker(opts, keep_findings)  # first: it reads the rules file
    spec = network_spec(opts, checker)
    if dbc:  # the DBC's identifiers belong on the bus (the unknown-identifier rule)
        spec.known_cob_ids |= {i for i, _ in dbc.messages}
    model = NetworkModel(spec)
    tracker = SdoTracker(timeout=opts.sdo_timeout, object_info=model.object_info)
    for node, request, response in model.sdo_channels:
        tracker.add_channel(node, request, response)
    skip = dbc.standard_ids if dbc else set()  # the DBC's layout wins over the profile's
    # CANopen FD (USDO on the SDO COB-IDs): --fd and the network file's canopen_fd keys
    fd: frozenset[int] | bool = True
    if opts.fd is not True and not spec.canopen_fd:
        fd = frozenset(opts.fd or ()) | {n for n, ns in spec.nodes.items() if ns.canopen_fd}
    processors = [
        SdoProcessor(tracker, identifier=model, fd_nodes=fd),
        model,
        PdoDecoder(model, skip),
        EmcyDecoder(model),
        SrdoDecoder(model, skip),
    ]
    if dbc:
        from cananalyze.decode.dbc_processor import DbcDecoder

        processors.insert(3, DbcDecoder(dbc))
    from cananalyze.checks.model_config import ModelConfig
    from cananalyze.decode.commissioning import Commissioning

    # boot stories and LSS steps (the event log's, JSONL's and the report's); a story is
    # judged against the heartbeat time in force as the checks see it
    config = ModelConfig(model)
    commissioning = Commissioning(
        model,
        lambda n, t: (checker.config if checker is not None else config).heartbeat_ms(n, t),
        opts.bitrate or spec.bitrate,  # the longest burst's event (a frame's time on the wire)
    )
    decoder = Decoder([*processors, DriveTracker(model), commissioning])
    model.attach(decoder)
    decoder.network = model
    if checker is not None:
        checker.config = config  # the model holds every declaration and the log
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
