"""The streamed SDO table's typed chunk columns (`outputs.sdo_chunks`) give the column
statistics and Arrow arrays that the values' lists give through `pandas_like`, whatever
mixes of kinds the chunks hold."""

from __future__ import annotations

import math
import random

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from cananalyze.core.columns import arrow_build as ab
from cananalyze.core.sdo_records import SdoRecords
from cananalyze.outputs.tables import pandas_like as pl
from cananalyze.outputs.tables import sdo_chunks as sc

NAN = float("nan")


def _values(piece) -> list:
    """The Python values a fast piece stands for (as the record lists held them)."""
    if piece is None:
        return []
    if isinstance(piece, sc.Labels):
        return [piece.labels[c] for c in piece.codes.tolist()]
    if isinstance(piece, pa.Array):
        return piece.to_pylist()
    if isinstance(piece, sc.Numbers):
        return sc._values(piece)
    if isinstance(piece, sc.Hex):
        return [
            bytes(r[:n]).hex()
            for r, n in zip(piece.raw.tolist(), piece.length.tolist(), strict=True)
        ]
    return piece.tolist()


def _same(a: pa.Array, b: pa.Array) -> None:
    assert a.type == b.type
    assert a.to_pylist() == b.to_pylist() or _nan_equal(a.to_pylist(), b.to_pylist())
    assert a.null_count == b.null_count
    assert a.equals(b)


def _nan_equal(x: list, y: list) -> bool:
    return len(x) == len(y) and all(
        u == v
        or (isinstance(u, float) and isinstance(v, float) and math.isnan(u) and math.isnan(v))
        for u, v in zip(x, y, strict=True)
    )


def _check(chunks: list[tuple[list, object, np.ndarray | None]], as_object: bool = False):
    """chunks of (mine, fast piece, order): same stats, decision and arrays as from the lists."""
    stats, ref = pl.ColumnStats(), pl.ColumnStats()
    cols, lists = [], []
    for mine, fast, order in chunks:
        both = list(mine) + _values(fast)
        values = both if order is None else [both[i] for i in order.tolist()]
        lists.append(values)
        ref.update(values)
        sc.take_in(stats, list(mine), fast)
        cols.append(sc.merge(list(mine), fast, order))
    assert (stats.kinds, stats.lo, stats.hi, stats.rows) == (ref.kinds, ref.lo, ref.hi, ref.rows)
    how = ref.decide(as_object)
    assert stats.decide(as_object) == how
    for col, values in zip(cols, lists, strict=True):
        _same(sc.to_arrow(col, how[0]), pl.convert(values, how[0]))
    return how[0]


def _order(n_mine: int, n_fast: int, seed: int = 0) -> np.ndarray | None:
    if not n_mine:
        return None
    slots = np.concatenate(
        (np.sort(random.Random(seed).sample(range(n_mine + n_fast), n_mine)), np.zeros(0))
    )
    rest = np.setdiff1d(np.arange(n_mine + n_fast), slots)
    return np.argsort(np.concatenate((slots, rest)), kind="stable")


def _case(mine: list, fast) -> tuple[list, object, np.ndarray | None]:
    return mine, fast, _order(len(mine), len(_values(fast)))


FLOATS = np.array([0.5, -0.0, 1e300, 3.0])
INTS = np.array([0, -7, 2**40, 5], np.int64)


@pytest.mark.parametrize("as_object", [False, True])
@pytest.mark.parametrize(
    "chunks",
    [
        # numbers from the fast path, gaps and odd values from the tracker
        [([], FLOATS), ([1.5, None], FLOATS), ([NAN], FLOATS[:1])],
        [([], INTS), ([None, 3], INTS), ([], INTS[:0])],
        [([], INTS), ([2**63], INTS)],  # beyond int64: uint64 (or text as object)
        [([], INTS), ([2**64], INTS)],  # beyond uint64: text
        [([-1], INTS), ([2**63 + 5], INTS)],  # no numeric type holds both
        [([], INTS), (["x"], INTS)],  # ints then a string
        [([2.5], INTS), ([True], INTS)],  # a float and a bool among ints
        [([pl.MISSING], FLOATS), ([], FLOATS)],
        # fast values as objects (the SDO value column)
        [([], np.array([1, None, 3], object)), (["s"], np.array([4], object))],
        [([], np.array([1, 2], object)), ([], np.array([2.5, None], object))],
        [([], np.array(["a", None], object)), ([7], np.array(["b"], object))],
        [([], np.array([1.5, NAN], object)), ([None], np.array([2**70], object))],
        [([], np.array([True, False], object)), ([], np.array([True], object))],
        [([], np.array([-(2**53) + 1, 2**53 - 1, 0, -5], object))],  # text of ints, exact
        [([], np.array([2**53, -(2**53), 9], object)), ([None], np.array([1], object))],
        [([], np.array([b"raw", 1], object))],
        # int values from the fast path with None gaps (the SDO value column)
        [([], sc.Numbers(np.array([1, 0, -3], np.int64), np.array([False, True, False])))],
        [
            (["t"], sc.Numbers(np.array([5, 0]), np.array([False, True]))),
            ([2**63], sc.Numbers(np.array([1]), None)),
        ],
        [([1.5], sc.Numbers(np.array([0, 0]), np.array([True, True])))],
        [
            ([None], sc.Numbers(np.array([2**53 + 1, 7]), None)),
            ([], sc.Numbers(np.array([0]), np.array([True]))),
        ],
        # labels (direction, constants, names) and prebuilt strings (data)
        [([], sc.Labels(np.array([0, 1, 1], np.int8), ["download", "upload"]))],
        [(["x", None], sc.Labels(np.zeros(3, np.int8), [None]))],
        [
            ([5, None], sc.Labels(np.zeros(3, np.int8), [None])),
            ([], sc.Labels(np.zeros(2, np.int8), [None])),
        ],
        [
            ([1.5], sc.Labels(np.zeros(2, np.int8), [None])),
            ([2**64], sc.Labels(np.zeros(1, np.int8), [None])),
        ],
        [([], sc.Labels(np.zeros(4, np.int8), [None]))],  # nothing at all: null (or float)
        [([NAN], sc.Labels(np.zeros(2, np.int8), [None]))],
        [([3], sc.Labels(np.array([0, 1], np.int8), ["ok", None]))],  # an int among texts
        [([None, "é"], sc.Labels(np.array([2, 0, 1], np.int8), ["a", None, "bc"]))],
        [
            (
                [],
                sc.hex_strings(
                    np.array([[1, 2, 3, 4], [255, 0, 0, 0]], np.uint8), np.array([4, 1])
                ),
            )
        ],
        [(["00ff", None, 3], sc.hex_strings(np.zeros((2, 4), np.uint8), np.array([0, 2])))],
        [([None], sc.Hex(np.array([[1, 2, 3, 4], [171, 0, 0, 0]], np.uint8), np.array([4, 1])))],
        [
            ([5], sc.Hex(np.zeros((1, 4), np.uint8), np.array([2]))),
            ([], sc.Hex(np.zeros((0, 4), np.uint8), np.zeros(0, np.int64))),
        ],
        [([], ab.strings(["a", None, "b"], large=True)), (["c"], ab.strings([None], large=True))],
        # chunks with only the tracker's records, and empty ones
        [([1.0, None, NAN], None), ([], None), ([2, 3], None)],
        [(["a", None], None), ([None], None), ([4], None)],
        [([2**63, None], None), ([1], None)],
        [([[1], {"a": 1}], None)],
    ],
)
def test_chunks_match_lists(chunks, as_object):
    _check([_case(c[0], c[1] if len(c) > 1 else None) for c in chunks], as_object)


def test_random_mixes():
    """Random chunks of every piece kind and value kind, many times over."""
    rng = random.Random(7)
    pool = [
        lambda: rng.randint(-5, 5),
        lambda: rng.choice([2**63, 2**64 - 1, -(2**63), 2**53 + 1]),
        lambda: rng.random() * 100,
        lambda: rng.choice([None, NAN, pl.MISSING]),
        lambda: rng.choice(["upload", "a", "é", ""]),
        lambda: rng.choice([True, False]),
    ]

    def fast_piece(n: int):
        kind = rng.randrange(7)
        if kind == 6:
            miss = np.array([rng.random() < 0.3 for _ in range(n)], bool)
            return sc.Numbers(np.array([rng.randint(-9, 9) for _ in range(n)], np.int64), miss)
        if kind == 0:
            return np.array([rng.random() for _ in range(n)])
        if kind == 1:
            return np.array([rng.randint(-(2**40), 2**40) for _ in range(n)], np.int64)
        if kind == 2:
            picks = rng.sample(pool, 2)
            return np.array([rng.choice(picks)() for _ in range(n)] + [None], object)[:n]
        if kind == 3:
            labels = rng.choice([["download", "upload"], [None], ["ok", None]])
            return sc.Labels(
                np.array([rng.randrange(len(labels)) for _ in range(n)], np.int8), labels
            )
        if kind == 4:
            return sc.hex_strings(
                np.array(
                    [[rng.randrange(256) for _ in range(4)] for _ in range(n)], np.uint8
                ).reshape(n, 4),
                np.array([rng.randrange(5) for _ in range(n)], np.int64),
            )
        return None

    for trial in range(300):
        chunks = []
        for _ in range(rng.randrange(1, 4)):
            n = rng.randrange(0, 6)
            fast = fast_piece(n)
            picks = rng.sample(pool, rng.randrange(1, 3))
            mine = [rng.choice(picks)() for _ in range(rng.randrange(0, 4))]
            if fast is None and not mine:
                mine = [None]
            chunks.append(_case(mine, fast))
        _check(chunks, as_object=trial % 2 == 1)


def test_take_strings_and_int_texts():
    arr = ab.strings(["ab", None, "", "ééé", "z"], large=True)
    order = np.array([4, 1, 0, 3, 2, 0])
    assert sc.take_strings(arr, order).to_pylist() == ["z", None, "ab", "ééé", "", "ab"]
    assert sc.take_strings(arr.slice(1, 3), np.array([2, 0])).to_pylist() == ["ééé", None]
    v = np.array([0, -1, 9, 10, -99, 2**53 - 1, -(2**53) + 1, 123456789], np.int64)
    miss = np.zeros(len(v), bool)
    miss[2] = True
    for as_float in (False, True):
        got = sc._int_texts(v, miss, as_float).to_pylist()
        want = [
            None if m else str(float(x)) if as_float else str(x)
            for x, m in zip(v.tolist(), miss, strict=True)
        ]
        assert got == want
    hexed = sc.hex_strings(np.array([[0xAB, 1, 2, 3], [9, 9, 9, 9]], np.uint8), np.array([3, 0]))
    assert hexed.to_pylist() == ["ab0102", ""]


@pytest.mark.parametrize("seed", range(4))
def test_take_strings_is_pc_take(seed):
    """The kernel called by name gives pc.take's array (type, nulls, offsets), and its
    error on an index out of range."""
    import pyarrow.compute as pc

    rng = random.Random(seed)
    words = [None, "", "a", "ééé", "x" * 40, "\x1f"]
    arr = ab.strings([rng.choice(words) for _ in range(rng.randrange(0, 60))], large=True)
    if len(arr) > 4:
        arr = arr.slice(2)
    order = np.array([rng.randrange(len(arr)) for _ in range(70)] if len(arr) else [], np.int64)
    got = sc.take_strings(arr, order)
    want = pc.take(arr, ab.numeric(order))
    assert got.type == want.type and got.equals(want)
    with pytest.raises(IndexError):
        sc.take_strings(arr, np.array([len(arr)]))


def test_int_column_decode_matches_decode_column():
    """`decode_int_column` (the export's numbers) holds what `decode_column` gives, for every type."""
    from cananalyze.protocol.datatypes import DATA_TYPES, decode_column, decode_int_column

    rng = np.random.default_rng(3)
    raw = rng.integers(0, 256, (64, 4), dtype=np.uint8)
    raw[:4] = [[0xFF] * 4, [0x80, 0, 0, 0x80], [0, 0x80, 0, 0], [0x7F, 0xFF, 0xFF, 0xFF]]
    length = rng.integers(0, 5, 64)
    ints = 0
    for code in DATA_TYPES:
        want = decode_column(raw, length, code)
        got = decode_int_column(raw, length, code)
        if got is None:
            assert not all(type(v) is int for v in want) or not want
            continue
        ints += 1
        values, none = got
        assert [
            None if n else v for v, n in zip(values.tolist(), none.tolist(), strict=True)
        ] == want
    assert ints >= 6


@pytest.mark.parametrize("cut", ["rows", "bytes"])
@pytest.mark.parametrize("fmt", ["parquet", "csv"])
@pytest.mark.parametrize(
    ("name", "size", "kept"),
    [("faults.log", 50, False), ("faults.log", 997, True), ("commissioning.log", 7, True)],
)
def test_sdo_written_as_chunks_come_is_the_file_written_at_close(
    tmp_path, monkeypatch, fmt, name, size, kept, cut
):
    """The sdo table written chunk by chunk on the writer thread while the column types hold
    is byte for byte the file written whole at close; when a later chunk changes a type
    (faults.log in 50-frame batches: an abort code after none) it is dropped and written at close.
    """
    from conftest import SAMPLES
    from exported import decoded_batches

    from cananalyze.outputs.tables import stream as table_stream
    from cananalyze.outputs.tables.stream import TableSink as StreamTables

    if cut == "rows":
        monkeypatch.setattr(table_stream, "ROW_GROUP", 8)
    else:  # row groups cut by their size in bytes (wide SDO rows)
        monkeypatch.setattr(table_stream, "ROW_GROUP_BYTES", 1500)
    log, kw = SAMPLES / name, {"network": str(SAMPLES / "network.toml")}
    spec = None
    chunks = 0
    for out, speculate in (("spec", True), ("whole", False)):
        with StreamTables(tmp_path / out, fmt) as st:
            if not speculate:
                st._sdo_spec = False
            for batch in decoded_batches(log, size, **kw):
                st.write(batch)
            if speculate:
                spec, chunks = st._sdo_spec, st._sdo_chunks
            st.close()
    assert bool(spec) is kept
    a = (tmp_path / "spec" / f"sdo.{fmt}").read_bytes()
    assert a == (tmp_path / "whole" / f"sdo.{fmt}").read_bytes()
    if fmt == "parquet" and kept:
        import pyarrow.parquet as pq

        meta = pq.ParquetFile(tmp_path / "spec" / "sdo.parquet").metadata
        sizes = [meta.row_group(i).num_rows for i in range(meta.num_row_groups)]
        assert min(sizes) > 0  # no empty row group after the last chunk
        # one chunk (all SDO rows in one batch), cut by bytes, is one row group
        assert len(sizes) > 1 or (cut == "bytes" and chunks == 1)


def test_hex_texts_as_bytes_hex():
    from cananalyze.core.sdo_records import hex_texts

    rng = np.random.default_rng(1)
    raw = rng.integers(0, 256, (500, 4), dtype=np.uint8)
    raw[:5] = 0
    length = rng.integers(0, 5, 500)
    want = [bytes(r[:n]).hex() for r, n in zip(raw.tolist(), length.tolist(), strict=True)]
    assert hex_texts(raw, length) == want
    assert sc.hex_strings(raw, length).to_pylist() == want
    assert hex_texts(raw[:0], length[:0]) == []


def _record_batch(t0: float, records: list[dict]):
    from cananalyze.core.frames import FrameBatch
    from cananalyze.core.records import DecodedBatch

    n = 4
    fb = FrameBatch.allocate(n, ("can0",))
    fb.t[:] = t0 + np.arange(n) * 0.001
    fb.can_id[:] = 0x181
    batch = DecodedBatch(fb, np.zeros(n, np.uint8), np.ones(n, np.int16), np.zeros(n, np.uint8))
    batch.records = SdoRecords([(k % n, {"kind": "sdo"} | r) for k, r in enumerate(records)])
    return batch


def _sdo(**kw) -> dict:
    base = {
        "t_start": 1.0,
        "t": 1.5,
        "latency_ms": 0.5,
        "node": 3,
        "direction": "upload",
        "protocol": "segmented",
        "index": 0x1008,
        "subindex": 0,
        "size": 4,
        "data": "41424344",
        "value": 7,
        "name": "x",
        "result": "ok",
        "abort_code": None,
        "abort_text": None,
        "detail": None,
    }
    return base | kw


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_tracker_only_chunks_of_every_kind_as_capture(tmp_path, fmt):
    """Chunks holding only the tracker's records (no fast path): ints then texts in one
    column, gaps, an abort after none, values beyond int64, missing keys, empty batches.
    The sdo file reads back as pandas' from_records table of the same records (what
    load()'s Capture builds), through pandas' own Parquet file of it; CSV cell by cell."""
    from exported import assert_csv_is, assert_parquet_is

    from cananalyze.core.sdo_records import SDO_TABLE_COLUMNS
    from cananalyze.outputs.tables.stream import TableSink as StreamTables

    gone = _sdo()
    del gone["detail"], gone["latency_ms"]
    chunks = [
        [_sdo(), _sdo(value=None, size=None, data=None)],
        [],
        [_sdo(value="text", abort_code=0x06020000, abort_text="no object", result="abort")],
        [_sdo(value=2**63 + 1, node=None, t_start=NAN), gone],
        [_sdo(value=1.5, subindex=2**64 - 1, latency_ms=3)],
    ]
    with StreamTables(tmp_path / "new", fmt) as st:
        for i, recs in enumerate(chunks):
            st.write(_record_batch(10.0 + i, recs))
        st.close()
    records = [{"kind": "sdo"} | r for recs in chunks for r in recs]
    want = pd.DataFrame.from_records(records, columns=list(SDO_TABLE_COLUMNS))
    want["value"] = want["value"].astype(object)  # mixed ints, floats, strings, as load()
    assert want["subindex"].dtype == np.uint64 and want["value"].map(type).nunique() > 2
    if fmt == "parquet":
        assert_parquet_is(want, tmp_path / "new" / "sdo.parquet")
    else:
        assert_csv_is(want, tmp_path / "new" / "sdo.csv")


@pytest.mark.parametrize(
    "values",
    [
        np.array([1.5, NAN, -0.0]),
        np.array([NAN, NAN]),
        np.zeros(0),
        np.array([-(2**63), 2**63 - 1, 0], np.int64),
        np.zeros(0, np.int64),
    ],
)
def test_update_array_as_update_of_the_list(values):
    a, b = pl.ColumnStats(), pl.ColumnStats()
    a.update_array(values)
    b.update(values.tolist())
    assert (a.kinds, a.lo, a.hi, a.rows) == (b.kinds, b.lo, b.hi, b.rows)
    with pytest.raises(TypeError):
        a.update_array(np.array(["x"], object))


@pytest.mark.parametrize("n", [0, 1, 7])
def test_take_in_constant_labels_as_update_of_the_list(n):
    """A constant fast-path column (one label, code 0 on every row) is taken in as the
    list of its values would be, rows and kinds alike, with no rows too."""
    for label in ("ok", None, 0):
        got, want = pl.ColumnStats(), pl.ColumnStats()
        sc.take_in(got, ["x"], sc.Labels(np.zeros(n, np.int8), [label]))
        want.update(["x", *[label] * n])
        assert (got.rows, got.kinds, got.decide()) == (want.rows, want.kinds, want.decide())
