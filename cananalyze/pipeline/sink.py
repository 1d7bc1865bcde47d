"""Sink: the one interface every output implements, from the terminal to a Parquet folder.

`pipeline.run` opens every sink before the first frame is read (so a bad
destination fails before the work), writes each decoded batch to each of them in
the same order, ticks them on a wall clock when the source is live, and then
finishes them all, then commits them all (a file appears only complete, and only
when every output could be finished) or, when anything failed or the user stopped it,
aborts them all (nothing half-written is left behind).
A sink reads only what the decoder put on the batch; it never decodes again.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cananalyze.core.records import DecodedBatch
    from cananalyze.pipeline.state import Run


class Sink:
    """Base with do-nothing defaults; a sink overrides what it needs."""

    #: the sink reads `batch.events` / `batch.states`: the pipeline builds them once for all
    needs_events: bool = False
    #: the file or folder it writes: an OSError without a file name (a full disk seen by a
    #: writer thread or a library) is given this one, so the message names the output
    dest: str | None = None

    def open(self, run: Run) -> None:
        """Before the first batch: check the destination, keep what the run says."""
        self.run = run

    def write(self, batch: DecodedBatch) -> None:
        """One decoded batch (the last one, from the decoder's finish, may have no frames)."""

    def tick(self, now: float) -> None:
        """Wall-clock time (live sources only), for deadlines and periodic flushes."""

    def close(self) -> None:
        """After the last batch: finish and commit (atomically, for files)."""

    def finish(self) -> None:
        """The pipeline's first half of close: everything but making files appear. A run
        with several outputs finishes them all, then commits them all, so an output that
        fails leaves none of the others committed (an export is all or nothing)."""
        self.close()

    def commit(self) -> None:
        """The second half: rename the finished temporary files over their targets."""

    def abort(self) -> None:
        """The run failed or was stopped: drop everything not yet committed."""
