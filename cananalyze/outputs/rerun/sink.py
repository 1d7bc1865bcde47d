"""Rerun as a pipeline sink: an .rrd file (`export --rrd`), a spawned viewer (`--rerun`)
or a running one (`--connect HOST:PORT`), streamed batch by batch by `StreamRrd`."""

from __future__ import annotations

import socket
import sys
from pathlib import Path
from urllib.parse import urlparse

from cananalyze.core.errors import UsageError
from cananalyze.outputs.rerun.send import grpc_url
from cananalyze.pipeline.sink import Sink


class RerunSink(Sink):
    needs_events = True

    def __init__(
        self,
        path: str | Path | None = None,
        connect: str | None = None,
        spawn: bool = False,
        bitrate: int | None = None,
    ) -> None:
        if path is None and not connect and not spawn:
            raise ValueError("RerunSink needs an .rrd file, a viewer to connect to, or spawn")
        self.path = path
        self.dest = str(path) if path is not None else None
        self.connect = connect
        self.bitrate = bitrate
        self.stream = None
        self.counts: dict[str, int] = {}

    def open(self, run) -> None:
        super().open(run)
        if self.connect:
            reachable(self.connect)
        from cananalyze.outputs.rerun.stream import StreamRrd

        self.stream = StreamRrd(
            self.path,
            run.name,
            str(run.options.network or ""),
            self.bitrate or run.options.bitrate,
            connect=self.connect,
        )

    def write(self, batch) -> None:
        self.stream.add(batch)

    def close(self) -> None:
        self.finish()
        self.commit()

    def finish(self) -> None:
        self.counts = self.stream.finish()

    def commit(self) -> None:
        self.stream.commit()

    def abort(self) -> None:
        if self.stream is not None:
            self.stream.abort()


def reachable(connect: str, timeout: float = 2.0) -> None:
    """Fail in one line, before decoding, when no viewer listens at `--connect`.

    Rerun's gRPC client connects in the background and only logs its failure, so
    the address is tried here with a plain TCP connection first.
    """
    url = urlparse(grpc_url(connect).replace("rerun+", "", 1))
    host, port = url.hostname or "127.0.0.1", url.port or 9876
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return
    except OSError as exc:
        raise UsageError(
            f"--connect {connect}: no Rerun viewer listens at {host}:{port} "
            f"({exc.strerror or exc}); start one with `rerun` or use --rerun"
        ) from None


class RerunLiveSink(Sink):
    """A live session's timelines to an .rrd file and/or a spawned viewer (`RerunLive`),
    sent every half second; kept (the .rrd footer written) however the session ends."""

    needs_events = True

    def __init__(
        self,
        rrd: str | Path | None = None,
        spawn: bool = False,
        bitrate: int | None = None,
        name: str = "live",
    ) -> None:
        if not rrd and not spawn:
            raise ValueError("RerunLiveSink needs an .rrd file, a viewer, or both")
        if rrd:
            from cananalyze.core.atomic import check_writable

            check_writable(rrd)
        self.rrd, self.spawn, self.bitrate, self.name = rrd, spawn, bitrate, name
        self.live = None

    def open(self, run) -> None:
        super().open(run)
        from cananalyze.outputs.rerun.live import RerunLive

        self.live = RerunLive(
            rrd=self.rrd,
            spawn=self.spawn,
            bitrate=self.bitrate,
            name=self.name,
            network=str(run.options.network or ""),
        )

    def write(self, batch) -> None:
        self.live.add(batch)

    def tick(self, now: float) -> None:
        self.live.flush_due()

    def close(self) -> None:
        self._finish()

    def abort(self) -> None:
        self._finish()

    def _finish(self) -> None:
        if self.live is not None:
            self.live.close()
            self.live = None
            if self.rrd:
                print(f"wrote {self.rrd}", file=sys.stderr)
