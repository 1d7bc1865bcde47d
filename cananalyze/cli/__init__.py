"""Command-line interface: one thin module per subcommand.

Ctrl-C (or SIGTERM) before `main` runs, while Python imports the program, ends it
without a traceback: this package is imported first by `python -m cananalyze` and
by the `cananalyze` script, so its hook is in place for every later import.

For the same reason it tells OpenBLAS (numpy's) to start one thread: its worker threads
spin when numpy loads, 0.06 s CPU of every command (half of numpy's import), and the
program does no linear algebra they could share. A user's own setting is kept.
"""

import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _quiet_interrupt(typ, value, tb) -> None:
    if issubclass(typ, KeyboardInterrupt):
        return  # the interpreter still exits as interrupted (status 130)
    sys.__excepthook__(typ, value, tb)


if sys.excepthook is sys.__excepthook__:
    sys.excepthook = _quiet_interrupt
