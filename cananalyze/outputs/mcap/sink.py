"""`--mcap FILE` as a pipeline sink: the chunked, time-merged MCAP of `StreamMcap`."""

from __future__ import annotations

from pathlib import Path

from cananalyze.decode.node_load import run_bitrate
from cananalyze.decode.node_tally import node_profiles
from cananalyze.outputs.mcap.stream import StreamMcap
from cananalyze.pipeline.sink import Sink


class McapSink(Sink):
    needs_events = True

    def __init__(self, path: str | Path, compression: str = "zstd") -> None:
        self.path = path
        self.dest = str(path) if path is not None else None
        self.compression = compression
        self.stream: StreamMcap | None = None
        self.counts: dict[str, int] = {}

    def open(self, run) -> None:
        super().open(run)
        self.stream = StreamMcap(
            self.path,
            self.compression,
            source=run.name,
            network=str(run.options.network or ""),
        )

    def write(self, batch) -> None:
        self.stream.add(batch)

    def close(self) -> None:
        self.finish()
        self.commit()

    def finish(self) -> None:
        self.stream.profiles = node_profiles(self.run.network)
        self.stream.bitrate = run_bitrate(self.run)
        self.counts = self.stream.finish(self.run.problems.count)

    def commit(self) -> None:
        self.stream.commit()

    def abort(self) -> None:
        if self.stream is not None:
            self.stream.abort()
