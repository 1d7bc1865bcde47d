"""`cananalyze` entry point: builds the sub-command parsers and turns errors into exit codes.

Exit codes: 0 ok, 1 check violations, 2 usage or input error. Bad input never
shows a traceback: CananalyzeError becomes one line on stderr.
"""

from __future__ import annotations

import argparse
import importlib
import signal
import sys

from cananalyze.cli import options as options_
from cananalyze.core.errors import CananalyzeError
from cananalyze.runtime import allocator, imports
from cananalyze.runtime.gcpolicy import fewer_collections

# One module per sub-command, each with add_parser(subparsers) and run(args) -> int.
SUBCOMMANDS = [
    "decode",
    "check",
    "report",
    "export",
    "live",
    "simulate",
    "devices",
    "od",
    "boot",
    "diff",
    "fleet",
    "query",
]
# Commands that read a whole log batch by batch: they get the allocator settings.
BATCH_COMMANDS = {"decode", "check", "report", "export", "od", "boot", "fleet"}


# `cananalyze fleet compact DATASET`: `fleet` takes inputs as positionals, so its second
# word is read as an input unless turned into the command of its own here (a log named
# `compact` stays an input when `--out` is given)
NESTED = {("fleet", "compact"): "fleet-compact"}


def _nested(argv: list[str]) -> list[str]:
    command = NESTED.get(tuple(argv[:2]))
    if command is None or any(a == "--out" or a.startswith("--out=") for a in argv):
        return argv
    return [command, *argv[2:]]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cananalyze",
        description="CANopen bus traffic analyser and log decoder.",
    )
    options_.add(parser, "version")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        try:
            module = importlib.import_module(f"{__package__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"{__package__}.{name}":
                continue  # sub-command not part of this build
            raise
        module.add_parser(sub)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C would be: every output is aborted the same way (no
    temporary file survives `kill`), and the exit status says which signal it was."""


def _terminate(signum, frame) -> None:
    if frame is not None and frame.f_code.co_name == "__del__":
        # Python would print the exception as "ignored" and go on: raise it again once
        # out of the finaliser (a pyarrow writer's __del__ was seen here)
        signal.signal(signal.SIGALRM, _terminate)
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        return
    raise Terminated


def program() -> int:
    """The `cananalyze` program (console script, `python -m cananalyze`): `main` plus what
    only a process of its own may change (python-can imported without asammdf)."""
    imports.install()
    return main()


def main(argv: list[str] | None = None) -> int:
    try:
        old = signal.signal(signal.SIGTERM, _terminate)
    except ValueError:
        old = None  # not the main thread (an embedding program): its own handling stays
    try:
        return _main(argv)
    finally:
        if old is not None:
            signal.signal(signal.SIGTERM, old)


def _main(argv: list[str] | None) -> int:
    try:
        parser = build_parser()
        args = parser.parse_args(_nested(sys.argv[1:] if argv is None else list(argv)))
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        if args.command in BATCH_COMMANDS:
            allocator.tune()
        with fewer_collections():
            return int(args.func(args) or 0)
    except CananalyzeError as exc:
        print(f"cananalyze: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # output piped into `head` and closed: not an error worth a traceback
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)
        return 0
    except Terminated:
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        return 130
    except OSError as exc:
        # an output that cannot be written (disk full, unwritable path, also when a
        # writer thread hits it): one line naming the file, not a traceback
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"cananalyze: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
