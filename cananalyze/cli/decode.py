"""`cananalyze decode LOG`: every frame annotated, as text or JSONL, with filters and a summary."""

from __future__ import annotations

import argparse
import contextlib
import sys

from ..errors import UsageError
from .common import add_input_options, report_problems
from .timeline import Timelines, add_timeline_options

# Readers, numpy and the decoder are imported in run(): `cananalyze --help` builds
# every sub-command's parser and must stay fast.


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "decode",
        help="annotate every frame of a log",
        description="Decode a CANopen log: every frame named for what it is.",
    )
    add_input_options(p)
    p.add_argument("--format", choices=["text", "jsonl"], default="text", help="output format")
    p.add_argument("--no-color", action="store_true", help="no ANSI colours even on a terminal")
    p.add_argument("--node", metavar="N[,N]", help="only frames of these node-IDs")
    p.add_argument(
        "--service",
        metavar="S[,S]",
        help="only these services (nmt, sync, time, emcy, tpdo, rpdo, pdo, sdo, heartbeat, ...)",
    )
    p.add_argument(
        "--from",
        dest="t_from",
        type=float,
        metavar="S",
        help="start, seconds after the first frame",
    )
    p.add_argument(
        "--to", dest="t_to", type=float, metavar="S", help="end, seconds after the first frame"
    )
    p.add_argument("--summary", action="store_true", help="print only the summary")
    p.add_argument("--sdo", action="store_true", help="print only the SDO transaction table")
    p.add_argument(
        "--signals",
        action="store_true",
        help="print only decoded PDO values, one signal record per value (t, node, pdo, signal, value, unit)",
    )
    p.add_argument(
        "--check",
        action="store_true",
        help="run the CANopen rules too: findings appear in the output at their frames",
    )
    p.add_argument(
        "--rules",
        metavar="FILE",
        help="rules file for --check (docs/rules-file.md); implies --check",
    )
    p.add_argument(
        "--bitrate", type=int, metavar="BIT/S", help="bus bitrate, for the bus load in --summary"
    )
    p.add_argument("-o", "--output", metavar="FILE", help="write to FILE instead of stdout")
    add_timeline_options(p)
    p.set_defaults(func=run)


def _node_set(text: str | None):
    import numpy as np

    if not text:
        return None
    try:
        nodes = [int(x, 0) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UsageError(f"--node takes node-IDs like 5 or 5,6 (got {text!r})") from None
    return np.array(nodes, np.int16)


_RECORD_SERVICES = {"sdo": {"sdo_request", "sdo_response"}, "signal": {"tpdo", "rpdo"}}


def _record_passes(rec: dict, args: argparse.Namespace, nodes, services, t0: float) -> bool:
    """Records obey the same filters as frames (findings pass the service filter)."""
    if nodes is not None and rec.get("node") not in set(nodes.tolist()):
        return False
    wanted = _RECORD_SERVICES.get(rec.get("kind"))
    if services is not None and wanted is not None and not wanted & {s.label for s in services}:
        return False
    t = rec.get("t")
    if t is not None and args.t_from is not None and t - t0 < args.t_from:
        return False
    return not (t is not None and args.t_to is not None and t - t0 > args.t_to)


def run(args: argparse.Namespace) -> int:
    from ..io.source import open_log
    from ..protocol.services import parse_services
    from .pipeline import build_decoder

    try:
        services = parse_services(args.service) if args.service else None
    except ValueError as exc:
        raise UsageError(f"--service: {exc}") from None
    nodes = _node_set(args.node)
    checker = None
    if args.check or args.rules:
        from ..checks.build import build_checker

        checker = build_checker(args.rules)  # a bad rules file fails before the log is read
    source = open_log(args.log, strict=args.strict, fmt=args.input_format)
    decoder = build_decoder(args)
    timing = None
    if checker is not None:
        from ..checks.build import attach_checker

        timing = attach_checker(decoder, checker)  # its timing analysis serves --summary too
    elif args.summary:
        from ..checks.engine import Checker

        timing = Checker(rules=[])  # timing analysis only: columnar, cheap
        decoder.processors.append(timing)
    from ..outputs.atomic import atomic_write

    with contextlib.ExitStack() as stack:
        # -o FILE appears only when complete: an interrupted or failed run leaves none
        out = sys.stdout
        if args.output:
            try:
                out = stack.enter_context(atomic_write(args.output))
            except OSError as exc:
                raise UsageError(
                    f"-o {args.output}: cannot write there: {exc.strerror or exc}"
                ) from None
        timelines = stack.enter_context(Timelines(args))
        _decode_to(out, args, source, decoder, timing, services, nodes, timelines)
    return 0


def _decode_to(
    out, args: argparse.Namespace, source, decoder, timing, services, nodes, timelines
) -> None:
    import numpy as np

    from ..io.prefetch import prefetch
    from ..outputs.summary import Summary

    summary = Summary()
    only_records = args.sdo
    if args.signals:
        from ..outputs.text.signals import SignalWriter

        writer = SignalWriter(out, args.format)
    elif args.format == "jsonl":
        from ..outputs.jsonl.rows import JsonlWriter

        # in the caller's thread: a worker gained ~1 s of 16 at 10M frames for 100-200 MB
        # more peak (JSONL batches are wider than text ones)
        writer = JsonlWriter(out, frames=not only_records)
    else:
        from ..outputs.text.writer import TextWriter

        color = out.isatty() and not args.no_color
        # finished lines are written by a thread while the next batch decodes
        writer = TextWriter(
            out, color=color, only_records=only_records, background=not args.summary
        )
    t0 = None
    svc_codes = np.array(sorted(services), np.uint8) if services else None
    batches = prefetch(source.batches())
    try:
        for fb in batches:
            batch = decoder.decode(fb)
            if t0 is None and len(fb):
                t0 = float(fb.t[0])
            summary.add(batch)
            if timelines:
                timelines.add(batch)
            if args.summary:
                continue
            mask = None
            if (
                nodes is not None
                or svc_codes is not None
                or args.t_from is not None
                or args.t_to is not None
            ):
                mask = np.ones(len(fb), bool)
                if nodes is not None:
                    mask &= np.isin(batch.node, nodes)
                if svc_codes is not None:
                    mask &= np.isin(batch.service, svc_codes)
                if args.t_from is not None:
                    mask &= fb.t - t0 >= args.t_from
                if args.t_to is not None:
                    mask &= fb.t - t0 <= args.t_to
            if mask is not None:
                batch.records = [
                    (row, rec)
                    for row, rec in batch.records
                    if _record_passes(rec, args, nodes, services, t0)
                ]
            writer.write(batch, mask)
        tail = decoder.finish()
        summary.add(tail)
        if timelines:
            timelines.add(tail)
        if not args.summary:
            writer.write(tail)
        close = getattr(writer, "close", None)
        if close is not None:
            close()  # the text writer's thread: done, its error raised here
    finally:
        close = getattr(writer, "close", None)
        if close is not None:
            with contextlib.suppress(Exception):  # already failing: the first error wins
                close()
        batches.close()  # stops the reader thread before its problems are reported
        out.flush()
        if not args.strict:  # strict: the InputError already names the first problem, in one line
            report_problems(source.problems)
    if args.summary:
        # --bitrate wins; else the network file's `bitrate`
        bitrate = args.bitrate or decoder.network.spec.bitrate
        print("\n".join(summary.lines(bitrate, source.problems.count)), file=out)
        from ..outputs.summary import device_lines

        print("\n".join(device_lines(decoder.network, summary)), file=out)
        print("\n".join(timing.timing.lines(timing.nmt, timing.t0)), file=out)
    if timelines:
        timelines.finish(source.problems)
