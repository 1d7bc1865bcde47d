"""The Parquet layout of the exported tables, decided by measurement (issue 23).

    python benchmarks/bench_tables.py DIR            # DIR: an `export --parquet` folder
    python benchmarks/bench_tables.py DIR --repeat 5

Reads the frames, signals and events tables of an export back into memory and
writes each again in several layouts: the one `outputs/tables` writes and the
alternatives it was chosen over (payload as hex text, statistics on every column,
dictionary encoding on the numeric columns too, signals one row per value).
Each variant is timed in CPU seconds (user + system of this process: the Parquet
encoder runs on Arrow's threads) beside wall time, best of `--repeat`, the
variants interleaved in rounds so the machine's load hits all alike; the file's
size is printed too. Reading the file back is timed with a DuckDB query on `t`
(what the statistics are kept for).
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cananalyze.outputs.tables.stream import EVENTS, FRAMES, SIGNALS  # noqa: E402
from cananalyze.outputs.tables.writer import ROW_GROUP  # noqa: E402


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)  # microseconds (os.times: 10 ms ticks)
    return r.ru_utime + r.ru_stime


def _options(spec, table: pa.Table, **change) -> dict:
    """The writer keywords of `spec` (its per-column compression included), changed."""
    opts = {**spec.parquet_options(), "compression": spec.compression(table.column_names, "snappy")}
    if "use_dictionary" in change and "column_encoding" in opts:  # dictionaries, not DELTA
        del opts["column_encoding"]
        opts["use_byte_stream_split"] = list(spec.split) or False
    return {**opts, **change}


def _hex(table: pa.Table) -> pa.Table:
    """The frames table with the payload as lowercase hex text (the layout before issue 23)."""
    i = table.schema.get_field_index("data")
    data = table.column("data")
    text = pa.chunked_array(
        [pa.array([b.hex() for b in chunk.to_pylist()], pa.string()) for chunk in data.chunks]
    )
    return table.set_column(i, "data", text)


def _long(wide: pa.Table) -> pa.Table:
    """The signals table one row per value (t, node, pdo, cob_id, signal, value): as before."""
    keys = ("t", "node", "pdo", "cob_id")
    parts = []
    for name in wide.column_names:
        if name in keys:
            continue
        col = wide.column(name)
        keep = pc.is_valid(col)
        sel = wide.select(list(keys)).filter(keep)
        n = sel.num_rows
        parts.append(
            sel.append_column("signal", pa.array([name] * n).dictionary_encode()).append_column(
                "value", col.filter(keep)
            )
        )
    table = pa.concat_tables(parts, promote_options="permissive")
    return table.sort_by([("t", "ascending")])


LABELS = ["channel", "service"]  # the frames table's string columns
MESSAGE = ["kind", "level", "node", "message"]
SMALL = ["channel", "can_id", "dlc", "flags", "service", "node", "pdo"]  # the layout before


def variants(folder: Path) -> list[tuple[str, pa.Table, dict]]:
    frames = pq.read_table(folder / "frames.parquet")
    events = pq.read_table(folder / "events.parquet")
    signals = pq.read_table(folder / "signals.parquet")
    hexed = _hex(frames)
    out = [
        ("frames: as written", frames, _options(FRAMES, frames)),
        ("frames: data as hex text", hexed, _options(FRAMES, hexed)),
        ("frames: statistics on all", frames, _options(FRAMES, frames, write_statistics=True)),
        ("frames: no statistics", frames, _options(FRAMES, frames, write_statistics=False)),
        ("frames: dictionary on all", frames, _options(FRAMES, frames, use_dictionary=True)),
        (
            "frames: dictionary on labels only",
            frames,
            _options(FRAMES, frames, use_dictionary=LABELS),
        ),
        (
            "frames: dictionary on small ints",
            frames,
            _options(FRAMES, frames, use_dictionary=SMALL),
        ),
        ("frames: snappy on every column", frames, _options(FRAMES, frames, compression="snappy")),
        ("events: as written", events, _options(EVENTS, events)),
        ("events: dictionary on all", events, _options(EVENTS, events, use_dictionary=True)),
        (
            "events: dictionary, message too",
            events,
            _options(EVENTS, events, use_dictionary=MESSAGE),
        ),
        ("events: statistics on all", events, _options(EVENTS, events, write_statistics=True)),
        ("signals: as written", signals, _options(SIGNALS, signals)),
    ]
    if "value" not in signals.column_names:  # the wide file: compare with one row per value
        long = _long(signals)
        opts = _options(SIGNALS, long, use_dictionary=["node", "pdo", "cob_id", "signal"])
        out.append(("signals: one row per value", long, opts))
    return out


def write(table: pa.Table, path: Path, opts: dict) -> None:
    with pq.ParquetWriter(path, table.schema, **opts) as w:
        w.write_table(table, row_group_size=ROW_GROUP)


def query(path: Path) -> float:
    """CPU seconds of a DuckDB time-window count on the file (statistics prune row groups)."""
    import duckdb

    con = duckdb.connect()
    lo, hi = con.execute(f"SELECT min(t), max(t) FROM read_parquet('{path}')").fetchone()
    mid = lo + (hi - lo) / 2
    c0 = _cpu()
    for _ in range(20):
        con.execute(
            f"SELECT count(*) FROM read_parquet('{path}') WHERE t BETWEEN {mid} AND {mid + 1}"
        ).fetchone()
    return _cpu() - c0


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", type=Path, help="an export --parquet folder")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    runs = variants(args.folder)
    best: dict[str, tuple[float, float]] = {}
    sizes: dict[str, int] = {}
    queries: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            for k, (label, table, opts) in enumerate(runs):
                path = Path(tmp) / f"{k}.parquet"
                w0, c0 = time.perf_counter(), _cpu()
                write(table, path, opts)
                wall, cpu = time.perf_counter() - w0, _cpu() - c0
                old = best.get(label, (float("inf"), float("inf")))
                best[label] = (min(old[0], cpu), min(old[1], wall))
                sizes[label] = path.stat().st_size
                queries[label] = min(queries.get(label, float("inf")), query(path))
    print(f"{'layout':34} {'CPU s':>7} {'wall s':>7} {'MB':>7} {'query CPU s':>11}")
    for label, _, _ in runs:
        cpu, wall = best[label]
        mb = sizes[label] / 1e6
        print(f"{label:34} {cpu:7.3f} {wall:7.3f} {mb:7.3f} {queries[label]:11.3f}")
    print(f"load average {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
