"""Exports as `cananalyze export` writes them, read back with independent readers and
compared with `cananalyze.load()` of the same log and options.

The README promises that the files hold the same tables as `load()` gives: the
export's sinks (TableSink, McapSink, RerunSink) and load()'s CaptureSink are
different code fed by the same pipeline, so each file is read with a third-party
reader (pandas/pyarrow, the `mcap` package, rerun's RrdReader) and checked against
load()'s DataFrames. Tests choose the batch size, to cut a log anywhere: an export
cut like live's batches is compared with load()'s sink over the same cuts.
"""

from __future__ import annotations

import collections
import dataclasses
import io
import json
import math
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from conftest import SAMPLES

import cananalyze
from cananalyze.api.capture import Capture
from cananalyze.api.options import load_options
from cananalyze.formats.source import read_all
from cananalyze.pipeline import Options, Run, build_checker, build_decoder, open_source, run

NETWORK = str(SAMPLES / "network.toml")
DEVICES = {k: "dat7014" for k in range(1, 17)}  # the generator's 16 nodes
DEMO_DEVICES = {3: "mcb560", 5: "dat7014"}
TABLES = ("frames", "signals", "sdo", "events", "findings", "nodes", "od")
FILES = {"parquet": "pq", "csv": "csv", "mcap": "x.mcap", "rrd": "x.rrd"}
# foxglove.LogLevel numbers of the events table's level names
FOXGLOVE_LEVEL = {"debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}
RERUN_LEVEL = {"debug": "DEBUG", "info": "INFO", "warning": "WARN", "error": "ERROR"}
RERUN_LEVEL["fatal"] = "CRITICAL"


def demo_capture(path: Path = SAMPLES / "demo.log", **options) -> Capture:
    """load() of a demo log with the demo's devices declared (and `options`)."""
    return cananalyze.load(path, device=DEMO_DEVICES, **options)


# --- running an export ---------------------------------------------------------------


class CutSource:
    """A log's frames in batches of `size` frames (the source's problems kept)."""

    def __init__(self, log: Path, opts: Options, size: int | None) -> None:
        self.inner = open_source(log, opts)
        self.path, self.problems, self.size = self.inner.path, self.inner.problems, size

    def batches(self):
        from cananalyze.core.frames import concat

        if self.size is None:
            yield from self.inner.batches()
            return
        fb = concat(self.inner.batches())
        for start in range(0, len(fb), self.size):
            yield fb.take(slice(start, start + self.size))


def export(
    log: Path,
    out: Path,
    formats: tuple[str, ...] = ("parquet",),
    size: int | None = None,
    bitrate: int | None = None,
    **load_kw,
) -> dict[str, Path]:
    """The files `cananalyze export LOG --parquet/--csv/--mcap/--rrd` writes, with the options
    `load(log, **load_kw)` takes (the rules on, as both run them by default), batches of
    `size` frames. Returns the path of each format's output."""
    from cananalyze.outputs.mcap.sink import McapSink
    from cananalyze.outputs.rerun.sink import RerunSink
    from cananalyze.outputs.tables.stream import TableSink

    opts = dataclasses.replace(load_options(**load_kw), bitrate=bitrate)
    out.mkdir(parents=True, exist_ok=True)
    paths = {fmt: out / FILES[fmt] for fmt in formats}
    sinks = []
    for fmt, path in paths.items():
        if fmt in ("parquet", "csv"):
            sinks.append(TableSink(path, fmt))
        elif fmt == "mcap":
            sinks.append(McapSink(path))
        else:
            sinks.append(RerunSink(path, bitrate=bitrate))
    run(CutSource(log, opts, size), build_decoder(opts, build_checker(opts)), sinks, opts)
    return paths


def export_run(log: Path, sinks: list, size: int | None = None, **load_kw) -> Run:
    """`pipeline.run` of the given sinks over a log cut in batches of `size`, rules on."""
    opts = load_options(**load_kw)
    return run(CutSource(log, opts, size), build_decoder(opts, build_checker(opts)), sinks, opts)


def load_cut(log: Path, size: int | None = None, **load_kw) -> Capture:
    """load() of the log, or, with `size`, load()'s sink (CaptureSink) over the same cut
    batches an export was given: a few records depend on where batches end (a rule's
    "N more like this" tally, an SDO protocol error placed on a batch's last row), so
    a cut export is compared with a Capture cut the same way."""
    if size is None:
        return cananalyze.load(log, **load_kw)
    from cananalyze.outputs.capture import CaptureSink

    sink = CaptureSink()
    export_run(log, [sink], size, **load_kw)
    return sink.capture


def decoded_batches(log: Path, size: int | None, network=None, device=None):
    """Decoded batches of `size` frames, no rules (for writers and event code fed directly)."""
    decoder = build_decoder(Options(network=network, devices=device or {}))
    fb = read_all(log)
    size = size or max(len(fb), 1)
    for start in range(0, len(fb), size):
        yield decoder.decode(fb.take(slice(start, start + size)))
    yield decoder.finish()


def backwards_log(log: Path, out: Path) -> Path:
    """The log's frames with their times reversed: every batch starts before the last ended."""
    fb = read_all(log)
    lines = [
        f"({t:.6f}) can0 {cid:03X}#{bytes(d[:n]).hex().upper()}"
        for t, cid, d, n in zip(fb.t[::-1], fb.can_id, fb.data, fb.dlc, strict=True)
    ]
    out.write_text("\n".join(lines) + "\n")
    return out


# --- Parquet and CSV -----------------------------------------------------------------


def _missing(v) -> bool:
    return v is None or v is pd.NA or (isinstance(v, float) and v != v)


def plain_columns(df: pd.DataFrame) -> pd.DataFrame:
    """What a table file holds of a DataFrame: Parquet has one type per column, so an object
    column of numbers, lists or mixed values (SDO `value`, findings `measured`) is text,
    None kept (as the README documents)."""
    mixed = {}
    for col in df.columns:
        if df[col].dtype == object:
            types = {type(v) for v in df[col] if not _missing(v)}
            if len(types) > 1 or (types and not types <= {str}):
                mixed[col] = df[col].map(lambda v: None if _missing(v) else str(v))
    return df.assign(**mixed) if mixed else df


def _pandas_file(df: pd.DataFrame, index: bool) -> io.BytesIO:
    buf = io.BytesIO()
    df.to_parquet(buf, engine="pyarrow", index=index)
    buf.seek(0)
    return buf


def _nullable(schema: pa.Schema) -> pa.Schema:
    """The schema without its metadata, every field nullable (as pandas writes them)."""
    return pa.schema([f.with_nullable(True) for f in schema.remove_metadata()])


def assert_parquet_is(df: pd.DataFrame, path: Path, index: bool = False) -> None:
    """The file reads back as pandas' own Parquet file of `df` would: the same Arrow
    schema and pandas metadata (dtypes, nullable integers, the index), the same frame."""
    df = plain_columns(df)
    ref = _pandas_file(df, index)
    got_schema, ref_schema = pq.read_schema(path), pq.read_schema(ref)
    # columns that are never null are written `not null` (TableSpec.required): the same
    # types otherwise, and pandas reads them back with the same dtypes (below)
    assert _nullable(got_schema) == ref_schema.remove_metadata(), path.name
    got_meta = json.loads(got_schema.metadata[b"pandas"])
    ref_meta = json.loads(ref_schema.metadata[b"pandas"])
    assert got_meta == ref_meta, path.name
    ref.seek(0)
    back = pd.read_parquet(path)
    pd.testing.assert_frame_equal(back, pd.read_parquet(ref))
    # and the values are load()'s, whatever dtype a Parquet round trip gives them
    pd.testing.assert_frame_equal(back, df, check_dtype=False, check_categorical=False)


SIGNAL_KEYS = ["t", "node", "pdo", "cob_id"]


def wide_signals_as_long(path: Path) -> pd.DataFrame:
    """The wide signals file (one row per PDO frame, a column per signal) back in the long
    form, by DuckDB's UNPIVOT (nulls dropped: a row's PDO does not carry that signal),
    each column's signal name and unit from its Parquet field metadata (pyarrow)."""
    import duckdb

    schema = pq.read_schema(path)
    keys = [*SIGNAL_KEYS, "bus"] if "bus" in schema.names else SIGNAL_KEYS  # several buses
    meta = {
        f.name: (f.metadata[b"signal"].decode(), f.metadata[b"unit"].decode())
        for f in schema
        if f.name not in keys
    }
    if not meta:
        return pd.DataFrame({c: [] for c in [*keys, "signal", "value", "unit"]})
    con = duckdb.connect()
    long = con.execute(
        f"UNPIVOT (SELECT * FROM read_parquet('{path}')) "
        f"ON COLUMNS(* EXCLUDE ({', '.join(keys)})) INTO NAME col VALUE value"
    ).df()
    long["signal"] = long["col"].map(lambda c: meta[c][0])
    long["unit"] = long["col"].map(lambda c: meta[c][1])
    return long[[*SIGNAL_KEYS, "signal", "value", "unit", *keys[len(SIGNAL_KEYS) :]]]


def assert_wide_signals_is(cap: Capture, path: Path) -> None:
    """signals.parquet holds load()'s signals, one row per PDO frame: by time, each frame
    once, and its values (DuckDB's UNPIVOT of it) are exactly `cap.signals`' rows."""
    table = pq.read_table(path)
    assert table.column_names[:4] == SIGNAL_KEYS, path.name
    assert table.num_rows == sum(len(s.t) for s in cap.series), path.name
    t = table.column("t").to_numpy()
    assert (np.diff(t) >= 0).all(), path.name
    key = [*SIGNAL_KEYS, "signal", *(["bus"] if "bus" in table.column_names else [])]

    def norm(df: pd.DataFrame) -> pd.DataFrame:
        df = df.astype({"node": "int64", "cob_id": "int64", "pdo": str, "signal": str})
        df = df.astype({"unit": str, "value": "float64", "t": "float64"})
        return df.sort_values([*key, "value"], kind="stable").reset_index(drop=True)

    got, want = norm(wide_signals_as_long(path)), norm(cap.signals)
    pd.testing.assert_frame_equal(got[want.columns], want, check_dtype=False)
    # and the file is load()'s signals_by_frame, as pandas reads it (the signal columns
    # in the order they first come: in a log whose times go back, the order written)
    back = pd.read_parquet(path)
    like = bool((np.diff(cap.batch.t) < 0).any())
    pd.testing.assert_frame_equal(
        back, cap.signals_by_frame, check_categorical=False, check_like=like
    )


def assert_parquet_tables(cap: Capture, folder: Path) -> None:
    """The folder holds the seven table files, each load()'s table (signals in its wide
    layout, whose long view is load()'s `signals`)."""
    assert sorted(p.name for p in folder.iterdir()) == sorted(f"{n}.parquet" for n in TABLES)
    for name in TABLES:
        if name == "signals":
            assert_wide_signals_is(cap, folder / "signals.parquet")
            continue
        assert_parquet_is(getattr(cap, name), folder / f"{name}.parquet", index=name == "nodes")


def _csv_text(values: pd.Series) -> list:
    """A column as the CSV cells it must be read back as (None for an empty cell)."""
    kind = values.dtype.kind if isinstance(values.dtype, np.dtype) else None
    out = []
    for v in values.astype(object):
        if _missing(v) or (isinstance(v, str) and v == ""):
            out.append(None)  # CSV cannot tell an empty text from a missing one
        elif kind == "f" or isinstance(v, float):
            out.append(float(v))
        elif isinstance(v, (bool, np.bool_)):
            out.append("true" if v else "false")
        elif isinstance(v, (int, np.integer)):
            out.append(int(v))
        elif isinstance(v, bytes):  # frames.data: CSV is text, the payload as hex
            out.append(v.hex() or None)
        else:
            out.append(str(v))
    return out


def _csv_cells(cells: pd.Series, like: list) -> list:
    """CSV text parsed as the expected cells' types (pandas read every cell as text)."""
    out = []
    for text, want in zip(cells.tolist(), like, strict=True):
        if text == "":
            out.append(None)
        elif isinstance(want, float):
            out.append(float(text))
        elif isinstance(want, int):
            out.append(int(text))
        else:
            out.append(text)
    return out


def assert_csv_is(df: pd.DataFrame, path: Path) -> None:
    """The CSV file, read by pandas as text, holds df's columns and values (numbers exact:
    the shortest text that reads back as the same float)."""
    df = plain_columns(df)
    got = pd.read_csv(path, dtype=str, keep_default_na=False)
    assert list(got.columns) == list(df.columns), path.name
    assert len(got) == len(df), path.name
    for col in df.columns:
        want = _csv_text(df[col])
        cells = _csv_cells(got[col], want)
        same = [
            a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and b != b)
            for a, b in zip(cells, want, strict=True)
        ]
        assert all(same), (
            path.name,
            col,
            [(a, b) for a, b, s in zip(cells, want, same, strict=True) if not s][:3],
        )


def assert_csv_tables(cap: Capture, folder: Path) -> None:
    assert sorted(p.name for p in folder.iterdir()) == sorted(f"{n}.csv" for n in TABLES)
    for name in TABLES:
        df = getattr(cap, name)
        assert_csv_is(df.reset_index() if name == "nodes" else df, folder / f"{name}.csv")


def assert_same_table_files(a: Path, b: Path, fmt: str = "parquet") -> None:
    """Two exports of the same log hold the same tables (CSV: byte for byte)."""
    for name in TABLES:
        if fmt == "csv":
            assert (a / f"{name}.csv").read_bytes() == (b / f"{name}.csv").read_bytes(), name
            continue
        fa, fb = pq.read_schema(a / f"{name}.parquet"), pq.read_schema(b / f"{name}.parquet")
        assert fa == fb and fa.metadata == fb.metadata, name
        pd.testing.assert_frame_equal(
            pd.read_parquet(a / f"{name}.parquet"), pd.read_parquet(b / f"{name}.parquet")
        )


# --- MCAP ------------------------------------------------------------------------------


@dataclass
class Mcap:
    """An MCAP file as the `mcap` package reads it (CRCs validated). `messages`: per
    topic, (log time, publish time, data) in file order."""

    messages: dict[str, list[tuple[int, int, bytes]]]
    schemas: dict[str, tuple[str, str, dict]]  # topic -> (schema name, encoding, JSON schema)
    encodings: dict[str, str]  # topic -> message encoding
    metadata: dict[str, dict[str, str]]
    attachments: dict[str, bytes]
    summary: object
    in_time_order: list[tuple[str, int, bytes]]  # every message as a player merges chunks

    def docs(self, topic: str) -> list[dict]:
        """A topic's payloads in log-time order, parsed with json.loads."""
        return [json.loads(d) for t, _, d in self.in_time_order if t == topic]

    def times(self, topic: str) -> list[int]:
        return [lt for t, lt, _ in self.in_time_order if t == topic]


def read_mcap(path: Path) -> Mcap:
    from mcap.reader import make_reader

    messages: dict[str, list] = collections.defaultdict(list)
    schemas, encodings = {}, {}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        for sc, ch, m in reader.iter_messages(log_time_order=False):
            messages[ch.topic].append((m.log_time, m.publish_time, m.data))
            schemas[ch.topic] = (sc.name, sc.encoding, json.loads(sc.data))
            encodings[ch.topic] = ch.message_encoding
        summary = reader.get_summary()
        f.seek(0)
        ordered = [
            (ch.topic, m.log_time, m.data)
            for _, ch, m in make_reader(f).iter_messages(log_time_order=True)
        ]
        f.seek(0)
        meta = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
        f.seek(0)
        att = {a.name: a.data for a in make_reader(f).iter_attachments()}
    return Mcap(dict(messages), schemas, encodings, meta, att, summary, ordered)


def _ns(t) -> list[int]:
    """Each float's exact nearest ns (a Fraction is the float's exact value), as MCAP keeps them."""
    return [max(0, round(Fraction(x) * 10**9)) for x in np.asarray(t, np.float64).tolist()]


def _json_value(v):
    v = v.item() if isinstance(v, np.generic) else v
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _json_type(values: np.ndarray) -> str:
    if values.dtype == bool:
        return "boolean"
    return "integer" if np.issubdtype(values.dtype, np.integer) else "number"


def assert_mcap_is(cap: Capture, path: Path) -> Mcap:
    """The MCAP file holds load()'s log: a topic per PDO with its signal values (exact
    integers), the NMT states per node, the event log as foxglove.Log, every frame."""
    m = read_mcap(path)
    expected: dict[str, int] = {}
    for s in cap.series:
        expected[f"/node/{s.node}/{s.pdo}"] = len(s.t)
    states = collections.defaultdict(list)
    for e in cap.state_changes:
        states[e.node].append(e)
    for node, evs in states.items():
        expected[f"/node/{node}/nmt_state"] = len(evs)
    if len(cap.events):
        expected["/canopen/events"] = len(cap.events)
    if len(cap.frames):
        expected["/can/frames"] = len(cap.frames)
    assert {t: len(v) for t, v in m.messages.items()} == expected
    # the summary's statistics agree with the messages read
    topic_of = {c.id: c.topic for c in m.summary.channels.values()}
    stats = m.summary.statistics
    assert {topic_of[k]: v for k, v in stats.channel_message_counts.items()} == expected
    assert stats.message_count == sum(expected.values())
    assert all(lt == pt for msgs in m.messages.values() for lt, pt, _ in msgs)
    assert set(m.encodings.values()) <= {"json"}
    assert {enc for _, enc, _ in m.schemas.values()} <= {"jsonschema"}
    # signals: values and units of load()'s series, log time = frame time in ns
    for s in cap.series:
        topic = f"/node/{s.node}/{s.pdo}"
        name, _, schema = m.schemas[topic]
        assert name == f"cananalyze.node{s.node}.{s.pdo}"
        props = schema["properties"]
        assert list(props) == list(s.columns)
        for col, values in s.columns.items():
            assert props[col]["type"] == _json_type(values), (topic, col)
            unit = s.units.get(col)
            assert props[col].get("description") == (f"unit: {unit}" if unit else None)
        # in file order: a series' messages are written batch by batch, as load() joins them
        assert [lt for lt, _, _ in m.messages[topic]] == _ns(s.t), topic
        docs = [json.loads(d) for _, _, d in m.messages[topic]]
        want = [{k: _json_value(v[i]) for k, v in s.columns.items()} for i in range(len(s.t))]
        assert docs == want, topic
        for col, values in s.columns.items():  # integers stay integers (no float rounding)
            if np.issubdtype(values.dtype, np.integer):
                assert all(type(d[col]) is int for d in docs), (topic, col)
    for node, evs in states.items():
        topic = f"/node/{node}/nmt_state"
        assert m.schemas[topic][0] == "cananalyze.NmtState"
        assert m.docs(topic) == [{"state": e.message} for e in evs]
        assert m.times(topic) == _ns([e.t for e in evs])
    if len(cap.events):
        ev = cap.events
        assert m.schemas["/canopen/events"][0] == "foxglove.Log"
        docs = m.docs("/canopen/events")
        lines = cap.batch.line
        name = Path(str(cap.source)).name
        want = [
            {
                "message": msg,
                "level": FOXGLOVE_LEVEL[str(level)],
                "name": f"node {node}" if not _missing(node) else str(kind),
                "file": name,
                "line": int(lines[row]) if not _missing(row) and row < len(lines) else 0,
            }
            for msg, level, node, kind, row in zip(
                ev["message"], ev["level"], ev["node"], ev["kind"], ev["row"], strict=True
            )
        ]
        # ties in time may come in either order from different chunks: compare as multisets
        key = json.dumps
        got = [{k: d[k] for k in ("message", "level", "name", "file", "line")} for d in docs]
        assert sorted(zip(m.times("/canopen/events"), map(key, got), strict=True)) == sorted(
            zip(_ns(ev["t"]), map(key, want), strict=True)
        )
        for d, lt in zip(docs, m.times("/canopen/events"), strict=True):
            assert d["timestamp"]["sec"] * 10**9 + d["timestamp"]["nsec"] == lt
    if len(cap.frames):
        f = cap.frames
        assert m.schemas["/can/frames"][0] == "cananalyze.Frame"
        times = [lt for lt, _, _ in m.messages["/can/frames"]]
        assert times == _ns(f["t"])  # in file order: the frames are in time order across chunks
        docs = [json.loads(d) for _, _, d in m.messages["/can/frames"]]
        node = f["node"].astype("Int64").fillna(-1).astype(int).tolist()
        for key, want in (
            ("channel", f["channel"].astype(str).tolist()),
            ("can_id", f["can_id"].tolist()),
            ("dlc", f["dlc"].tolist()),
            ("data", [bytes(d).hex() for d in f["data"]]),
            ("flags", f["flags"].tolist()),
            ("service", f["service"].astype(str).tolist()),
            ("node", node),
        ):
            assert [d[key] for d in docs] == want, key
    meta = m.metadata["cananalyze"]
    assert meta["version"] == cananalyze.__version__
    assert meta["source"] == str(cap.source)
    assert meta["network"] == str(cap.network or "")
    assert meta["frames"] == str(len(cap.frames))
    assert meta["skipped_input"] == str(cap.problems.count)
    nodes = json.loads(m.attachments["nodes.json"])
    want_nodes = [
        {k: None if _missing(v) else _json_value(v) for k, v in row.items()}
        for row in cap.nodes.reset_index().to_dict("records")
    ]
    assert nodes == want_nodes
    return m


def assert_same_mcap(a: Path, b: Path) -> None:
    """Two exports of one log: each topic the same messages (an SDO transfer that ends in a
    later batch is written with that batch), the same schemas, metadata and attachments."""
    ma, mb = read_mcap(a), read_mcap(b)
    assert set(ma.messages) == set(mb.messages)
    for topic in ma.messages:
        assert sorted(ma.messages[topic]) == sorted(mb.messages[topic]), topic
    assert ma.schemas == mb.schemas
    assert ma.metadata == mb.metadata and ma.attachments == mb.attachments


# --- Rerun .rrd --------------------------------------------------------------------------


_SKIP = {"rerun.controls.RowId", "RecordingInfo:start_time"}


@dataclass
class Rrd:
    """An .rrd as rerun's own reader reads it: rows per entity, the static rows, the layout."""

    rows: dict[str, list[dict]]  # temporal rows, time as ns
    static: dict[str, dict]  # entity -> its static components
    layout: list[tuple]

    def values(self, entity: str, component: str) -> list[tuple[int, object]]:
        """(time ns, value) of each row, sorted (batches may send an entity's rows late)."""
        return sorted((r["time"], r[component][0]) for r in self.rows[entity])


def _layout(chunks) -> list[tuple]:
    """The blueprint's views and containers: names, origins, kinds and settings, without the
    random ids that tie them together or the time they were sent."""
    out = []
    for chunk in chunks:
        for r in chunk.to_record_batch().to_pylist():
            kept = tuple(
                sorted(
                    (k, repr(v))
                    for k, v in r.items()
                    if k not in ("rerun.controls.RowId", "log_time", "blueprint")
                    and not k.endswith((":contents", ":root_container"))
                )
            )
            if kept:
                out.append(kept)
    return sorted(out)


def read_rrd(path: Path, layout: bool = True) -> Rrd:
    """layout=False: the rows only (a live recording sends its layout again as it grows)."""
    from rerun.chunk import RrdReader

    reader = RrdReader(path)
    rows: dict[str, list[dict]] = collections.defaultdict(list)
    static: dict[str, dict] = collections.defaultdict(dict)
    for chunk in reader.stream():
        for r in chunk.to_record_batch().to_pylist():
            r = {k: v for k, v in r.items() if k not in _SKIP}
            if chunk.is_static:
                static[chunk.entity_path].update(r)
            elif r:
                if "time" in r:  # a Timestamp (epoch times) or a Timedelta (relative)
                    r["time"] = r["time"].value
                rows[chunk.entity_path].append(r)
    if not layout:
        return Rrd(dict(rows), dict(static), [])
    (blueprint,) = [s for s in reader.blueprints() if s.kind == "blueprint"]
    return Rrd(dict(rows), dict(static), _layout(reader.stream(store=blueprint)))


def _rrd_times(t) -> list[int]:
    """Frame times as a rerun timeline holds them: seconds times 1e9 as integer ns (a
    timestamp for epoch logs, a duration for relative times)."""
    return (np.asarray(t, np.float64) * 1e9).astype(np.int64).tolist()


def assert_rrd_is(cap: Capture, path: Path, bitrate: int | None = None) -> Rrd:
    """The .rrd holds load()'s log: a series per signal with its values, the NMT lanes,
    the event log with levels, the bus load, and a layout naming every PDO."""
    from cananalyze.protocol.busload import frame_bits, load_series

    r = read_rrd(path)
    expected = {}
    for s in cap.series:
        for col, values in s.columns.items():
            expected[f"/node/{s.node}/{s.pdo}/{col}"] = len(values)
    states = collections.defaultdict(list)
    for e in cap.state_changes:
        states[e.node].append(e)
    for node, evs in states.items():
        expected[f"/node/{node}/nmt"] = len(evs)
    if len(cap.events):
        expected["/events"] = len(cap.events)
    starts, load = (
        load_series(cap.batch.t, frame_bits(cap.batch.flags, cap.batch.dlc), 0.1, bitrate)
        if len(cap.batch)
        else (np.zeros(0), np.zeros(0))
    )
    if load.size:
        expected["/bus/load"] = int(load.size)
    assert {k: len(v) for k, v in r.rows.items()} == expected
    for s in cap.series:
        for col, values in s.columns.items():
            entity = f"/node/{s.node}/{s.pdo}/{col}"
            want = sorted(
                zip(_rrd_times(s.t), np.asarray(values, np.float64).tolist(), strict=True)
            )
            got = r.values(entity, "Scalars:scalars")
            assert [t for t, _ in got] == [t for t, _ in want], entity
            assert np.array_equal([v for _, v in got], [v for _, v in want], equal_nan=True)
            unit = s.units.get(col)
            assert r.static[entity]["SeriesLines:names"] == [f"{col} [{unit}]" if unit else col]
    for node, evs in states.items():
        got = r.values(f"/node/{node}/nmt", "StateChange:state")
        assert got == sorted(
            zip(_rrd_times([e.t for e in evs]), [e.message for e in evs], strict=True)
        )
    if len(cap.events):
        ev = cap.events
        got = sorted(
            (row["time"], row["TextLog:level"][0], row["TextLog:text"][0])
            for row in r.rows["/events"]
        )
        levels = [RERUN_LEVEL[str(v)] for v in ev["level"]]
        assert got == sorted(zip(_rrd_times(ev["t"]), levels, ev["message"].tolist(), strict=True))
    if load.size:
        got = r.values("/bus/load", "Scalars:scalars")
        assert [t for t, _ in got] == _rrd_times(starts)
        assert [v for _, v in got] == load.tolist()
        name = "bus load [%]" if bitrate else "bus load [bit/s]"
        assert r.static["/bus/load"]["SeriesLines:names"] == [name]
    header = r.static["/"]
    assert header["cananalyze_version"] == [cananalyze.__version__]
    assert header["source"] == [str(cap.source)]
    assert header.get("network", [""]) == [str(cap.network or "")]
    views = {dict(row).get("ViewBlueprint:display_name") for row in r.layout}
    for s in cap.series:  # a plot per PDO, named with its COB-ID
        assert repr([f"node {s.node} {s.pdo.upper()} (0x{s.cob_id:03X})"]) in views
    return r


def assert_same_rrd(a: Path, b: Path) -> None:
    """Two exports of one log: the same rows per entity (late SDO events in a later
    batch), the same static components and the same layout."""
    ra, rb = read_rrd(a), read_rrd(b)
    assert set(ra.rows) == set(rb.rows)
    for entity in ra.rows:
        key = lambda row: repr(sorted(row.items()))  # noqa: E731
        assert sorted(map(key, ra.rows[entity])) == sorted(map(key, rb.rows[entity])), entity
    assert ra.static == rb.static
    assert ra.layout == rb.layout
