"""Run: what the sinks may ask about the run in progress (options, source, decoder, counts)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from cananalyze.core.errors import ProblemLog

if TYPE_CHECKING:
    from cananalyze.checks.engine import Checker
    from cananalyze.decode.model import NetworkModel

from cananalyze.pipeline.decoder import Decoder
from cananalyze.pipeline.options import Options
from cananalyze.pipeline.source import Source


@dataclass
class Run:
    """What the sinks may ask about the run in progress."""

    options: Options
    source: Source
    decoder: Decoder
    t0: float | None = None  # time of the log's first frame (text times count from it)
    frames: int = 0  # frames read
    shown: int = 0  # frames that passed the filters
    rows: int = 0  # rows written to the sinks so far (row numbers of events)
    t_last: float | None = None
    # frames per node (index node + 1, 0 = no node), counted when filtering: what to
    # tell a user whose --node matched nothing
    node_frames: np.ndarray = field(default_factory=lambda: np.zeros(129, np.int64))

    @property
    def problems(self) -> ProblemLog:
        return self.source.problems

    @property
    def network(self) -> NetworkModel | None:
        return self.decoder.network

    @property
    def checker(self) -> Checker | None:
        return self.decoder.checker

    @property
    def name(self) -> str:
        return str(self.source.path)
