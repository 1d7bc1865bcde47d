"""Assertions for pytest: check a log (path, FrameBatch or DecodedBatches) and fail readably.

Each helper raises AssertionError listing the findings (time, node, measured vs
expected, why), so a failing test explains itself. `Capture.assert_*` call these
with the capture's decoded columns and the configuration its pipeline saw (`config`).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from .checks.engine import Checker
from .checks.finding import Finding
from .checks.rule import Rule
from .frames import FrameBatch
from .records import DecodedBatch

Source = str | Path | FrameBatch | Iterable[DecodedBatch]


def run_rules(source: Source, rules: list[Rule], config=None) -> list[Finding]:
    """Run `rules` over a log path, a FrameBatch, or already decoded batches; return the findings."""
    from .decoder import Decoder
    from .sdo.processor import SdoProcessor
    from .sdo.tracker import SdoTracker

    checker = Checker(rules, config)
    if isinstance(source, (str, Path)):
        from .io.source import open_log

        decoder = Decoder([SdoProcessor(SdoTracker()), checker])
        for fb in open_log(source).batches():
            decoder.decode(fb)
        decoder.finish()
    elif isinstance(source, FrameBatch):
        decoder = Decoder([SdoProcessor(SdoTracker()), checker])
        decoder.decode(source)
        decoder.finish()
    else:
        # decoded batches: run the checker as a processor on each (copy records so the
        # caller's batches are not changed), then an empty end-of-log batch
        last = None
        for b in source:
            view = DecodedBatch(
                b.frames, b.service, b.node, b.pdo, b.notes, list(b.records), b.signals
            )
            checker.process(view)
            last = b
        tail = Decoder().decode(FrameBatch.empty(last.frames.channels if last else ()))
        checker.finish(tail)
    return checker.findings


def _fail(findings: list[Finding], what: str) -> None:
    from .outputs.junit import format_finding

    bad = [f for f in findings if f.fails]
    if bad:
        lines = "\n  ".join(format_finding(f) for f in bad[:20])
        more = f"\n  ... {len(bad) - 20} more" if len(bad) > 20 else ""
        raise AssertionError(f"{what}: {len(bad)} violation(s)\n  {lines}{more}")


def assert_heartbeat(
    source: Source, node: int, period_ms: float, tolerance: float = 0.1, config=None
) -> None:
    from .checks.rules.assert_heartbeat import AssertHeartbeat

    _fail(
        run_rules(
            source,
            [AssertHeartbeat(node=node, period_ms=period_ms, tolerance=tolerance)],
            config,
        ),
        f"heartbeat of node {node} every {period_ms:g} ms ± {tolerance:.0%}",
    )


def assert_no_emcy(
    source: Source, allow: Iterable[int] = (), node: int | None = None, config=None
) -> None:
    from .checks.rules.emcy import EmcyRule

    found = [
        f
        for f in run_rules(source, [EmcyRule(allow=list(allow))], config)
        if node is None or f.node == node
    ]
    _fail(found, "no EMCY" + (f" from node {node}" if node is not None else ""))


def assert_sdo_ok(source: Source, max_latency_ms: float | None = None, config=None) -> None:
    from .checks.rules.sdo import SdoRule

    _fail(
        run_rules(source, [SdoRule(max_latency_ms=max_latency_ms)], config),
        "all SDO transfers succeed",
    )


def assert_pdo_rate(source: Source, cob_id: int, min_hz: float, max_hz: float, config=None) -> None:
    from .checks.rules.assert_pdo_rate import AssertPdoRate

    _fail(
        run_rules(source, [AssertPdoRate(cob_id=cob_id, min_hz=min_hz, max_hz=max_hz)], config),
        f"PDO 0x{cob_id:03X} between {min_hz:g} and {max_hz:g} Hz",
    )


def assert_signal_range(
    source: Source, node: int, signal: str, lo: float, hi: float, config=None
) -> None:
    from .checks.rules.assert_signal import AssertSignal

    _fail(
        run_rules(source, [AssertSignal(node=node, signal=signal, min=lo, max=hi)], config),
        f"{signal} of node {node} within {lo:g}..{hi:g}",
    )


def assert_operational_after_boot(source: Source, node: int, within_s: float, config=None) -> None:
    from .checks.rules.assert_boot import AssertOperational

    _fail(
        run_rules(source, [AssertOperational(node=node, within_s=within_s)], config),
        f"node {node} operational within {within_s:g} s of boot-up",
    )


def assert_clean(
    source: Source, rules_file: str | Path | None = None, network_file: str | Path | None = None
) -> None:
    """Every default rule (or the rules file's) passes."""
    from .checks.build import build_checker

    checker = build_checker(rules_file, network_file)
    _fail(run_rules(source, checker.rules, checker.config), "all rules pass")
