"""`load()` and `check()`: a log decoded and checked by the one pipeline, as DataFrames or findings.

`Capture` here is the outputs' in-memory tables plus the `assert_*` helpers a test calls,
each judged as `cananalyze check` judges: per bus, against the configuration in force.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from cananalyze.api.options import load_options
from cananalyze.core.defaults import SDO_TIMEOUT
from cananalyze.core.finding import Finding
from cananalyze.core.records import DecodedBatch
from cananalyze.outputs import capture as tables
from cananalyze.outputs.capture import CaptureSink
from cananalyze.runtime.gcpolicy import fewer_collections


class Capture(tables.Capture):
    """A decoded log (DataFrames built on demand) with pytest-style assertions."""

    def _judged(self) -> tuple:
        """(source, config) for the `assert_*` helpers: the decoded batch and `config`; on
        a log of several buses each bus's own part and configuration (`assertions.ByBus`),
        judged apart as `check` judges them (node 5 on can0 and on can1: two devices)."""
        checkers = [] if self.checker is None else [self.checker, *self.checker.others]
        if len(checkers) < 2:
            return self.decoded(), self.config
        from cananalyze.api.assertions import ByBus
        from cananalyze.core.frames import OTHER_CHANNELS
        from cananalyze.core.records import SignalBlock

        fb = self.batch
        buses = [c.bus for c in checkers]
        other = buses.index(OTHER_CHANNELS) if OTHER_CHANNELS in buses else 0
        of_channel = np.array([buses.index(c) if c in buses else other for c in fb.channels])
        row_bus = of_channel[fb.channel] if len(fb) else np.zeros(0, np.intp)
        first = buses[0]
        rec_bus = self.record_bus or [None] * len(self.records)
        parts = []
        for k, c in enumerate(checkers):
            rows = np.flatnonzero(row_bus == k)
            pos = np.full(len(fb) + 1, rows.size, np.int64)  # a row not its: at the end
            pos[rows] = np.arange(rows.size)
            records = [
                (int(pos[row]) if 0 <= row < len(fb) else rows.size, rec)
                for (row, rec), bus in zip(self.records, rec_bus, strict=True)
                if (bus or first) == c.bus
            ]
            blocks = [
                SignalBlock(pos[s.rows], s.node, s.pdo, s.cob_id, s.columns, s.units)
                for s in self.series
                if (s.bus or first) == c.bus
            ]
            batch = DecodedBatch(
                fb.take(rows),
                self.service[rows],
                self.node[rows],
                self.pdo[rows],
                records=records,
                signals=blocks,
            )
            parts.append((c.bus, [batch], c.config))
        return ByBus(parts), None

    def assert_heartbeat(self, node: int, period_ms: float, tolerance: float = 0.1) -> None:
        """Every heartbeat gap of `node` within period_ms ± tolerance (a fraction)."""
        from cananalyze.api.assertions import assert_heartbeat

        source, config = self._judged()
        assert_heartbeat(source, node, period_ms, tolerance, config=config)

    def assert_no_emcy(self, allow: Iterable[int] = (), node: int | None = None) -> None:
        """No EMCY (other than the `allow`ed error codes), from any node or from `node`."""
        from cananalyze.api.assertions import assert_no_emcy

        source, config = self._judged()
        assert_no_emcy(source, allow, node, config=config)

    def assert_sdo_ok(self, max_latency_ms: float | None = None) -> None:
        """Every SDO transfer ends ok (no abort, timeout or protocol error), none slower."""
        from cananalyze.api.assertions import assert_sdo_ok

        source, config = self._judged()
        assert_sdo_ok(source, max_latency_ms, config=config)

    def assert_pdo_rate(self, cob_id: int, min_hz: float, max_hz: float) -> None:
        """The PDO on `cob_id` arrives at min_hz..max_hz over the log."""
        from cananalyze.api.assertions import assert_pdo_rate

        source, config = self._judged()
        assert_pdo_rate(source, cob_id, min_hz, max_hz, config=config)

    def assert_signal_range(self, node: int, signal: str, lo: float, hi: float) -> None:
        """Every decoded value of `signal` from `node` within lo..hi (and seen at all)."""
        from cananalyze.api.assertions import assert_signal_range

        source, config = self._judged()
        assert_signal_range(source, node, signal, lo, hi, config=config)

    def assert_operational_after_boot(self, node: int, within_s: float) -> None:
        """After each boot-up, `node` is operational within `within_s` seconds."""
        from cananalyze.api.assertions import assert_operational_after_boot

        source, config = self._judged()
        assert_operational_after_boot(source, node, within_s, config=config)


def load(
    path: str | Path,
    *,
    network: str | Path | None = None,
    eds: dict[int, str | Path] | list[str] | None = None,
    device: dict[int, str] | list[str] | None = None,
    strict: bool = False,
    input_format: str | None = None,
    sdo_timeout: float = SDO_TIMEOUT,
    rules: str | Path | None = None,
    dbc: str | Path | list[str | Path] | None = None,
    bitrate: int | None = None,
) -> Capture:
    """Decode and check a log into a Capture (DataFrames `frames`, `signals`, `sdo`,
    `events`, `findings`; `heartbeat(node)`; `assert_*` methods for pytest).

    eds / device map node-IDs to EDS/DCF/XDD/XDC files / built-in profile keys
    ({5: "dat7014"}), as `--eds 5=FILE` / `--device 5=KEY` do on the command line;
    network and rules are the files `--network` and `check --rules` take; dbc one or more
    DBC files (`--dbc`), whose messages join `signals`; bitrate the bus's (`--bitrate`,
    else the network file's): the nodes' share of the bus and the longest burst. The same
    pipeline as `cananalyze check` and `export`: the same findings and tables.
    """
    dbc = () if dbc is None else (dbc,) if isinstance(dbc, (str, Path)) else tuple(dbc)
    opts = load_options(
        network, eds, device, strict, input_format, sdo_timeout, rules, dbc=dbc, bitrate=bitrate
    )
    return load_with(path, opts)


def load_with(path: str | Path, opts) -> Capture:
    """load() with the pipeline's Options as the command line builds them (`diff`)."""
    from cananalyze.pipeline import build_checker, build_decoder, open_source, run

    checker = build_checker(opts)  # a bad rules file fails before the log is opened
    source = open_source(path, opts)
    sink = CaptureSink(Capture)
    with fewer_collections():
        run(source, build_decoder(opts, checker), [sink], opts)
    return sink.capture


def check(path, **options) -> list[Finding]:
    """The findings `cananalyze check` reports for a log, in time order (rules and network
    as keyword arguments, like `load()`); `[f for f in found if f.fails]` are violations."""
    from cananalyze.outputs.findings import FindingsSink
    from cananalyze.pipeline import build_checker, build_decoder, open_source, run

    opts = load_options(**options)
    checker = build_checker(opts)
    report = FindingsSink(quiet=True)
    run(open_source(path, opts), build_decoder(opts, checker), [report], opts)
    return report.findings.findings()  # Finding objects: what a Python caller reads
