"""The loop: every sink opened, each batch decoded once and written to all, then all finished and committed (or all aborted)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterable, Iterator

import numpy as np

from cananalyze.core.frames import FrameBatch
from cananalyze.core.records import DecodedBatch
from cananalyze.pipeline.decoder import Decoder
from cananalyze.pipeline.options import Options
from cananalyze.pipeline.sink import Sink
from cananalyze.pipeline.source import Source
from cananalyze.pipeline.state import Run
from cananalyze.runtime import signals


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
            "sdo": bool(labels & {"sdo_request", "sdo_response", "usdo_request", "usdo_response"}),
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
    from cananalyze.decode.events.build import EventBuilder

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
    from cananalyze.formats.live import LiveSource

    if isinstance(source, LiveSource):
        return _until_failure(source.batches(), ended)
    from cananalyze.formats.prefetch import prefetch

    return prefetch(source.batches())


def _until_failure(batches: Iterator[FrameBatch], ended: list) -> Iterator[FrameBatch]:
    from cananalyze.formats.live import LiveError, LiveOpenError

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
