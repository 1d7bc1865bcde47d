"""Assertions for pytest: check a log (path, FrameBatch or DecodedBatches) and fail readably.

Each helper raises AssertionError listing the findings (time, node, measured vs
expected, why), so a failing test explains itself. A path or FrameBatch goes
through the same pipeline as `cananalyze check` and `load()` (pass `network=`,
`device=`, `eds=` as to `load()`); `Capture.assert_*` call these with the
capture's decoded columns and the configuration its pipeline saw (`config`).
"""

from __future__ import annotations

import copy
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from cananalyze.checks.engine import Checker, whole_log
from cananalyze.checks.rule import Rule
from cananalyze.core.finding import Finding
from cananalyze.core.frames import FrameBatch
from cananalyze.core.records import DecodedBatch


@dataclass
class ByBus:
    """A decoded log of several buses (`Capture` gives it): each bus's batches and the
    configuration its checks saw, judged by one Checker per bus as the pipeline does
    (node 5 on can0 and on can1 are two devices)."""

    parts: list[tuple[str, list[DecodedBatch], object]]  # (bus, batches, config)


Source = str | Path | FrameBatch | Iterable[DecodedBatch] | ByBus


def run_rules(source: Source, rules: list[Rule], config=None, **options) -> list[Finding]:
    """Run `rules` over a log path, a FrameBatch, or already decoded batches; return the findings.

    `options`: `load()`'s keyword arguments (network, device, eds, rules, ...) for a path
    or FrameBatch: its rules are judged by the network model the pipeline builds from
    them. `config` is for decoded batches (a Capture's `config`).
    """
    if isinstance(source, (str, Path, FrameBatch)):
        from cananalyze.api.options import load_options
        from cananalyze.core.errors import UsageError
        from cananalyze.pipeline import build_decoder, open_source, run

        if config is not None:
            raise UsageError(
                "config= is for decoded batches; for a log give network=, device=, eds= or rules="
            )
        opts = load_options(**options)
        checker = Checker(rules)
        run(open_source(source, opts), build_decoder(opts, checker), [], opts)
        return checker.findings
    if isinstance(source, ByBus):
        return _run_buses(source, rules)
    checker = Checker(rules, config)
    last = None
    for last in source:
        checker.process(_view(last))
    checker.finish(_end(last))
    return checker.findings


def _view(b: DecodedBatch) -> DecodedBatch:
    """A batch for the checker to add to: the records copied, the caller's unchanged."""
    return DecodedBatch(b.frames, b.service, b.node, b.pdo, b.notes, list(b.records), b.signals)


def _end(last: DecodedBatch | None) -> DecodedBatch:
    """An empty end-of-log batch, of the channels of the log's last batch."""
    from cananalyze.pipeline import Decoder

    return Decoder().decode(FrameBatch.empty(last.frames.channels if last else ()))


def _run_buses(source: ByBus, rules: list[Rule]) -> list[Finding]:
    """One Checker per bus (a fresh copy of the rules each, that bus's configuration),
    times from the log's first frame, an assertion told absent only when no bus has its
    subject (`engine.whole_log`), a node silent at the end judged against the log's last
    frame whichever bus it was on: every bus's findings, each naming its bus."""
    checkers = []
    for k, (bus, _, config) in enumerate(source.parts):
        c = Checker(copy.deepcopy(rules) if k else rules, config)
        c.name_bus(bus)
        c.first_bus = k == 0
        checkers.append(c)
    frames = [b.frames.t for _, batches, _ in source.parts for b in batches if len(b)]
    for c in checkers:
        c.t0 = min(float(t[0]) for t in frames) if frames else None
    for c, (_, batches, _) in zip(checkers, source.parts, strict=True):
        for b in batches:
            c.process(_view(b))
    whole_log(checkers)
    end = max(float(t[-1]) for t in frames) if frames else None
    for c, (_, batches, _) in zip(checkers, source.parts, strict=True):
        c.t_last = end
        c.finish(_end(batches[-1] if batches else None))
    checkers[0].others = checkers[1:]
    return checkers[0].findings


def _fail(findings: list[Finding], what: str) -> None:
    from cananalyze.outputs.junit import format_finding

    bad = [f for f in findings if f.fails]
    if bad:
        lines = "\n  ".join(format_finding(f) for f in bad[:20])
        more = f"\n  ... {len(bad) - 20} more" if len(bad) > 20 else ""
        raise AssertionError(f"{what}: {len(bad)} violation(s)\n  {lines}{more}")


def assert_heartbeat(
    source: Source, node: int, period_ms: float, tolerance: float = 0.1, config=None, **options
) -> None:
    from cananalyze.checks.rules.assert_heartbeat import AssertHeartbeat

    rule = AssertHeartbeat(node=node, period_ms=period_ms, tolerance=tolerance)
    _fail(
        run_rules(source, [rule], config, **options),
        f"heartbeat of node {node} every {period_ms:g} ms ± {tolerance:.0%}",
    )


def assert_no_emcy(
    source: Source, allow: Iterable[int] = (), node: int | None = None, config=None, **options
) -> None:
    from cananalyze.checks.rules.emcy import EmcyRule

    found = [
        f
        for f in run_rules(source, [EmcyRule(allow=list(allow))], config, **options)
        if node is None or f.node == node
    ]
    _fail(found, "no EMCY" + (f" from node {node}" if node is not None else ""))


def assert_sdo_ok(
    source: Source, max_latency_ms: float | None = None, config=None, **options
) -> None:
    from cananalyze.checks.rules.sdo import SdoRule

    _fail(
        run_rules(source, [SdoRule(max_latency_ms=max_latency_ms)], config, **options),
        "all SDO transfers succeed",
    )


def assert_pdo_rate(
    source: Source, cob_id: int, min_hz: float, max_hz: float, config=None, **options
) -> None:
    from cananalyze.checks.rules.assert_pdo_rate import AssertPdoRate

    rule = AssertPdoRate(cob_id=cob_id, min_hz=min_hz, max_hz=max_hz)
    _fail(
        run_rules(source, [rule], config, **options),
        f"PDO 0x{cob_id:03X} between {min_hz:g} and {max_hz:g} Hz",
    )


def assert_signal_range(
    source: Source, node: int, signal: str, lo: float, hi: float, config=None, **options
) -> None:
    from cananalyze.checks.rules.assert_signal import AssertSignal

    rule = AssertSignal(node=node, signal=signal, min=lo, max=hi)
    _fail(
        run_rules(source, [rule], config, **options),
        f"{signal} of node {node} within {lo:g}..{hi:g}",
    )


def assert_operational_after_boot(
    source: Source, node: int, within_s: float, config=None, **options
) -> None:
    from cananalyze.checks.rules.assert_boot import AssertOperational

    rule = AssertOperational(node=node, within_s=within_s)
    _fail(
        run_rules(source, [rule], config, **options),
        f"node {node} operational within {within_s:g} s of boot-up",
    )
