"""MCAP export batch by batch (`export --mcap`, `decode --mcap`), memory flat in log length.

Laying out a whole Capture at once peaked at 2.1 GB for a 5M-frame log, so a
fleet log did not fit. Here each decoded batch's messages (PDO signals, NMT
state changes, events, raw frames; `topics` builds them) are merged by time and
written as chunks straight away. Schemas and channels are declared when their
topic first appears: MCAP allows Schema and Channel records anywhere in the data
section before their first message.

Within a batch, messages are in log-time order, ties in topic order (signals,
states, events, frames). An SDO transfer that ends a batch
or two after it began is a message in a later chunk than its time; MCAP readers
merge chunks by the time ranges in their indexes, so players show it in place.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np

from cananalyze.core.atomic import atomic_path
from cananalyze.core.columns.json_text import Texts
from cananalyze.core.records import DecodedBatch, SignalBlock, on_bus
from cananalyze.core.version import __version__
from cananalyze.decode.drive_tracker import STATE
from cananalyze.decode.events.build import EventState, batch_events_of
from cananalyze.decode.events.columns import KINDS, NO_NODE, NO_ROW
from cananalyze.decode.node_tally import NodeTally
from cananalyze.formats.mcap_bulk import BulkMcapWriter
from cananalyze.formats.mcap_frames import FRAME_SCHEMA, FRAMES_TOPIC, frame_payloads, log_time_ns
from cananalyze.outputs.mcap.topics import (
    DRIVE_SCHEMA,
    EVENTS_TOPIC,
    LOG_SCHEMA,
    STATE_SCHEMA,
    drive_payloads,
    drive_topic,
    event_payloads,
    signal_payloads,
    signal_schema,
    signal_topic,
    state_payloads,
    state_topic,
    write_merged,
    write_metadata,
)
from cananalyze.outputs.tables.writer import WriterThread


def batch_messages(
    fb,
    service,
    node,
    blocks,
    states,
    events,
    lines,
    file: str,
    drive=(),
    want=None,
    buses: bool = False,
    offset: int = 0,
) -> list[tuple]:
    """(channel key, topic, schema, log times ns, payloads) of one batch, per stream:
    signals (one stream per series, in the Capture's series order), NMT states per node,
    CiA 402 drive states per axis, events as foxglove.Log, raw frames. The one place that
    says which topic carries what: `export --mcap` writes these and `live --foxglove`
    serves them. `want(topic)` False leaves that stream's payloads None (not built: a
    live topic no client subscribed to costs nothing but its times). `buses`: the run
    has several buses, each decoded topic is per bus (`records.on_bus`); event rows count
    from `offset` (the batch's first row)."""
    out: list[tuple] = []
    keep = want or (lambda topic: True)

    def bus_of(row) -> str | None:  # the bus of a batch row, None for one bus or no row
        if not buses or row is None or not 0 <= row < len(fb):
            return None
        return fb.channel_label(int(fb.channel[row]))

    for n, pdo, cob, rows, columns, units in sorted(blocks, key=lambda b: b[:3]):
        parts = [(None, rows, columns)]
        if buses and len(rows):
            chans = fb.channel[rows]
            parts = []
            for c in np.unique(chans):  # one stream per bus (rows of a block keep order)
                sel = np.flatnonzero(chans == c)
                cols = columns if len(sel) == len(rows) else {k: v[sel] for k, v in columns.items()}
                parts.append((fb.channel_label(int(c)), rows[sel], cols))
        for bus, r, cols in parts:
            blk = SignalBlock(r, n, pdo, cob, cols, units)
            key = ("signals", bus, n, pdo, cob, tuple(cols))
            topic = on_bus(bus, signal_topic(blk))
            payload = signal_payloads(cols) if keep(topic) else None
            out.append((key, topic, signal_schema(blk), log_time_ns(fb.t[r]), payload))
    by_node: dict[tuple, list] = {}
    for e in states:
        bus = bus_of(None if e.row is None else e.row - offset)
        by_node.setdefault((e.node, bus or ""), []).append(e)
    for (n, bus), evs in sorted(by_node.items()):
        ns = log_time_ns(np.array([e.t for e in evs]))
        topic = on_bus(bus or None, state_topic(n))
        payload = state_payloads(evs) if keep(topic) else None
        out.append((("state", bus, n), topic, STATE_SCHEMA, ns, payload))
    by_drive: dict[tuple, list] = {}
    for c in drive:  # a batch's drive changes: the lane shows the states
        if c.kind == STATE:
            by_drive.setdefault((c.node, bus_of(c.row) or ""), []).append(c)
    for (n, bus), cs in sorted(by_drive.items()):
        ns = log_time_ns(np.array([c.t for c in cs]))
        topic = on_bus(bus or None, drive_topic(n))
        payload = drive_payloads(cs) if keep(topic) else None
        out.append((("drive", bus, n), topic, DRIVE_SCHEMA, ns, payload))
    if len(events) and not keep(EVENTS_TOPIC):
        out.append((("events",), EVENTS_TOPIC, LOG_SCHEMA, log_time_ns(np.sort(events.t)), None))
    elif len(events):
        order = np.lexsort((events.sort_key(), events.t))
        events = events.take(order)
        ns = log_time_ns(events.t)
        names = [
            f"node {n}" if n != NO_NODE else KINDS[k]
            for n, k in zip(events.node.tolist(), events.kind.tolist(), strict=True)
        ]
        if buses:
            local = events.row - offset
            names = [
                nm if (bus := bus_of(None if r == NO_ROW else lr)) is None else f"{bus} {nm}"
                for nm, r, lr in zip(names, events.row.tolist(), local.tolist(), strict=True)
            ]
        line = np.asarray(lines, np.int64)[order].tolist()
        payload = event_payloads(
            ns, events.level.tolist(), events.message.tolist(), names, file, line
        )
        out.append((("events",), EVENTS_TOPIC, LOG_SCHEMA, ns, payload))
    if len(fb):
        payload = frame_payloads(fb, service, node) if keep(FRAMES_TOPIC) else None
        out.append((("frames",), FRAMES_TOPIC, FRAME_SCHEMA, log_time_ns(fb.t), payload))
    return out


class StreamMcap:
    """Context manager: `add()` each DecodedBatch, `close(skipped)` at the end; the file
    appears (atomically) only then."""

    def __init__(
        self,
        path: str | Path,
        compression: str = "zstd",
        source: str = "",
        network: str = "",
        profiles: dict[int, tuple[str, str]] | None = None,
        chunk_bytes: int = 4 << 20,
    ) -> None:
        self.path = Path(path)
        self.source = str(source)
        self.network = network or ""
        self.profiles = profiles or {}
        self.bitrate: int | None = None  # the nodes' share of the bus (nodes.json)
        self._stack = contextlib.ExitStack()
        tmp = self._stack.enter_context(atomic_path(path))
        f = self._stack.enter_context(open(tmp, "wb"))
        self.w = BulkMcapWriter(
            f, f"cananalyze {__version__}", compression=compression, chunk_bytes=chunk_bytes
        )
        self.counts: dict[str, int] = {}
        self._channels: dict[tuple, int] = {}  # series key / topic -> channel id
        self._topics: dict[int, str] = {}
        self._event_state = EventState()
        self._nodes = NodeTally()
        self._file = Path(self.source).name
        self._lines = (0, np.zeros(0, np.int64))  # (first row, line numbers) of the last batch
        self.offset = 0
        self._buses = False  # several buses seen: decoded topics per bus (from then on)
        # one batch waits while one is written (the decoder is rarely the slower side)
        self._writer = WriterThread(depth=1)

    def __enter__(self) -> StreamMcap:
        return self

    def __exit__(self, typ, exc, tb) -> None:
        if exc is not None:
            self.abort(typ, exc, tb)

    def _channel(self, key: tuple, topic: str, schema: dict) -> int:
        ch = self._channels.get(key)
        if ch is None:
            sid = self.w.schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            ch = self._channels[key] = self.w.channel(topic, "json", sid)
            self._topics[ch] = topic
        return ch

    def add(self, batch: DecodedBatch) -> None:
        """Queue the batch's messages for the writer thread (merged by time there)."""
        fb = batch.frames
        off = self.offset
        events, states = batch_events_of(batch, off, self._event_state)
        self._nodes.add(batch, states, off)
        lines = self._line_numbers(events.row, fb.line, off) if len(events) else []
        if len(fb):
            self._lines = (off, fb.line)
        # what the job needs, not the batch (its notes and records would stay alive too)
        blocks = [(b.node, b.pdo, b.cob_id, b.rows, b.columns, b.units) for b in batch.signals]
        service, node = batch.service, batch.node
        drive = batch.drive
        self._buses = self._buses or len(fb.channels) > 1
        buses = self._buses
        try:
            self._writer.put(
                lambda: self._emit(
                    fb, service, node, blocks, states, events, lines, drive, buses, off
                )
            )
        except OSError as exc:  # the writer thread's: name the file it was writing
            raise _named(exc, self.path) from exc
        self.offset += len(fb)

    def _emit(
        self, fb, service, node, blocks, states, events, lines, drive=(), buses=False, off=0
    ) -> None:
        """One batch's messages, on the writer thread: its JSON columns (numpy, pyarrow
        and C work outside the GIL) are built beside the decoder; the writer lays out,
        compresses and writes the chunks on a thread of its own."""
        streams: list[tuple[int, np.ndarray, Texts]] = []
        for key, topic, schema, ns, payload in batch_messages(
            fb,
            service,
            node,
            blocks,
            states,
            events,
            lines,
            self._file,
            drive,
            buses=buses,
            offset=off,
        ):
            streams.append((self._channel(key, topic, schema), ns, payload))
        write_merged(self.w, streams)
        for ch, ns, _ in streams:
            topic = self._topics[ch]
            self.counts[topic] = self.counts.get(topic, 0) + len(ns)

    def _line_numbers(self, rows: np.ndarray, lines: np.ndarray, off: int) -> list[int]:
        """Input line of each event's frame row; 0 without one. Records the end of the log
        completes sit on the previous batch's last row."""
        out = np.zeros(len(rows), np.int64)
        for first, lns in (self._lines, (off, lines)):
            local = rows - first
            ok = (rows != NO_ROW) & (local >= 0) & (local < len(lns))
            out[ok] = lns[local[ok]]
        return out.tolist()

    def close(self, skipped: int = 0) -> dict[str, int]:
        """Metadata, attachments and the summary; the file replaces its target. Returns
        message counts per topic."""
        counts = self.finish(skipped)
        self.commit()
        return counts

    def commit(self) -> None:
        """The finished file replaces its target."""
        self._stack.close()

    def finish(self, skipped: int = 0) -> dict[str, int]:
        """close() but the rename."""
        try:
            self._writer.join()
            nodes = self._nodes.rows(self.profiles, bitrate=self.bitrate)
            write_metadata(self.w, self.source, self.network, self.offset, skipped, nodes)
            self.w.finish()
        except BaseException as exc:
            self.abort(type(exc), exc, exc.__traceback__)
            if isinstance(exc, OSError):
                raise _named(exc, self.path) from exc
            raise
        return self.counts

    def abort(self, typ=None, exc=None, tb=None) -> None:
        """Drop the temporary file (a cut-off export leaves no MCAP behind)."""
        with contextlib.suppress(BaseException):
            self._writer.join()
        self.w.abort()
        self._stack.__exit__(typ or RuntimeError, exc or RuntimeError("aborted"), tb)


def _named(exc: OSError, path: Path) -> OSError:
    """The error with the output file's name when it has none (the CLI prints it)."""
    if exc.filename:
        return exc
    return OSError(exc.errno, exc.strerror or str(exc), str(path))
