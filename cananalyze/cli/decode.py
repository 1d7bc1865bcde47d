"""`cananalyze decode LOG`: every frame annotated, as text or JSONL, with filters and a summary."""

from __future__ import annotations

import argparse
import contextlib
import sys

from cananalyze.cli import options as options_
from cananalyze.cli.common import DBC, options, report_problems, require_display_for_viewer
from cananalyze.core.errors import UsageError

# Readers, numpy and the decoder are imported in run(): `cananalyze --help` builds
# every sub-command's parser and must stay fast.


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "decode",
        help="annotate every frame of a log",
        description="Decode a CANopen log: every frame named for what it is.",
    )
    options_.add(p, *options_.INPUT, "format", "no_color", extra_names=DBC)
    options_.add(p, *options_.FILTERS, "time", "summary", "sdo", "signals", "check", "rules")
    options_.add(p, "bitrate", "output", "quiet", "mcap", "rerun", "connect")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from cananalyze.pipeline import build_checker, build_decoder, open_source

    if args.rerun and args.connect:
        raise UsageError("--rerun spawns a viewer, --connect uses a running one: give one of them")
    if args.rerun:
        require_display_for_viewer(
            "stream to a viewer running elsewhere with --connect HOST:PORT, or write a file "
            "with `cananalyze export LOG --rrd FILE`"
        )
    opts = options(args, checks=bool(args.check), timing=bool(args.summary))
    checker = build_checker(opts) if opts.checking or opts.timing else None
    source = open_source(args.log, opts)  # a bad rules file has failed already
    decoder = build_decoder(opts, checker)
    try:
        _decode(args, source, decoder, opts)
    except OSError as exc:
        if exc.filename or not args.output:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), args.output) from exc  # -o's file
    return 0


def _decode(args: argparse.Namespace, source, decoder, opts) -> None:
    from cananalyze.cli.common import run_with_progress
    from cananalyze.core.atomic import atomic_write

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
        sinks = [_main_sink(args, out), *_timeline_sinks(args)]
        sinks[0].dest = args.output
        # no bar while lines go to the terminal as they are decoded; --summary prints at
        # the end, after the bar is cleared
        streaming = not args.output and not args.summary and sys.stdout.isatty()
        quiet = args.quiet or streaming
        try:
            run_with_progress(source, decoder, sinks, opts, quiet=quiet)
        finally:
            out.flush()
            if not args.strict:  # strict: the InputError names the first problem, in one line
                report_problems(source.problems)


def _main_sink(args: argparse.Namespace, out):
    """What decode prints: the summary, the SDO table, the signals, or every frame."""
    if args.summary:
        from cananalyze.outputs.summary import SummarySink

        return SummarySink(out, args.format)
    if args.signals:
        from cananalyze.outputs.text.signals import SignalWriter

        return SignalWriter(out, args.format)
    if args.format == "jsonl":
        from cananalyze.outputs.jsonl.rows import JsonlWriter

        # in the caller's thread: a worker gained ~1 s of 16 at 10M frames for 100-200 MB
        # more peak (JSONL batches are wider than text ones)
        return JsonlWriter(out, frames=not args.sdo)
    from cananalyze.outputs.colour import use_colour
    from cananalyze.outputs.text.writer import TextWriter

    # finished lines are written by a thread while the next batch decodes
    return TextWriter(
        out, color=use_colour(out, args.no_color), only_records=args.sdo, background=True
    )


def _timeline_sinks(args: argparse.Namespace) -> list:
    sinks = []
    if args.mcap:
        from cananalyze.outputs.mcap.sink import McapSink

        sinks.append(McapSink(args.mcap))
    if args.rerun or args.connect:
        from cananalyze.outputs.rerun.sink import RerunSink

        sinks.append(RerunSink(connect=args.connect, spawn=args.rerun, bitrate=args.bitrate))
    return sinks
