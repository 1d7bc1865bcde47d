"""The one pipeline: options, a source, a decoder and the sinks, joined by one loop.

Every door goes through here: `decode`, `check`, `export`, `live`, `load()` and
the pytest assertions each turn what they were given into `Options`, open a
source, build the decoder and call `run` with their sinks. So no two outputs can
disagree about what a log holds: they read the same decoded batches.

    opts = Options(network="net.toml", rules="rules.yaml")
    source = open_source("run.blf", opts)
    run(source, build_decoder(opts), [TableSink("out", "parquet")], opts)
"""

from cananalyze.pipeline.decoder import Decoder, build_checker, build_decoder, network_spec
from cananalyze.pipeline.options import Options
from cananalyze.pipeline.run import run, unmatched_filter
from cananalyze.pipeline.sink import Sink
from cananalyze.pipeline.source import MemorySource, Source, open_source
from cananalyze.pipeline.state import Run

__all__ = [
    "Decoder",
    "MemorySource",
    "Options",
    "Run",
    "Sink",
    "Source",
    "build_checker",
    "build_decoder",
    "network_spec",
    "open_source",
    "run",
    "unmatched_filter",
]
