"""SdoRecords: one type for a batch's SDO transfers, tracker-made and fast-path alike.

The fast path's dicts are built only when read; the columns, the table, merging
and pickling must all see the transfers in the order they ended.
"""

from __future__ import annotations

import pickle

import numpy as np

from cananalyze.core.sdo_records import FastPart, RecordColumns, SdoColumns, SdoRecords


def _part(at, rows: list[int], built: list) -> FastPart:
    """A fast part at positions `at`; its fields are the built dicts, held."""
    cols, build = _fast(rows, built)
    return FastPart(np.asarray(at), cols, build, lambda: RecordColumns.of_records(build(None)))


def _fast(rows: list[int], built: list) -> tuple[SdoColumns, object]:
    m = len(rows)
    cols = SdoColumns(
        row=np.asarray(rows, np.int64),
        req_row=np.asarray(rows, np.int64) - 1,
        node=np.full(m, 7, np.int64),
        upload=np.ones(m, bool),
        index=np.arange(0x2000, 0x2000 + m, dtype=np.int64),
        subindex=np.zeros(m, np.int64),
        ok=np.array([True] * (m - 1) + [False]),
        latency=np.full(m, 1.5),
        t=np.asarray(rows, np.float64) / 10,
    )

    def build(js):
        js = range(m) if js is None else js.tolist()
        built.append(list(js))
        return [
            {
                "kind": "sdo",
                "node": 7,
                "index": 0x2000 + j,
                "result": "ok" if j < m - 1 else "abort",
            }
            for j in js
        ]

    return cols, build


def _records() -> tuple[SdoRecords, list]:
    """Positions: 0 tracker (row 0), 1-2 fast (rows 3, 5), 3 tracker (row 6), 4 fast (row 9)."""
    built: list = []
    recs = SdoRecords([(0, {"kind": "sdo", "node": 3, "result": "timeout", "latency_ms": None})])
    first = recs.reserve(2)
    recs.append(6, {"kind": "sdo", "node": None, "index": 0x1017, "result": "ok", "t": 0.6})
    last = recs.reserve(1)
    recs.defer(_part([first, first + 1, last], [3, 5, 9], built))
    return recs, built


def test_columns_and_table_without_building() -> None:
    recs, built = _records()
    assert len(recs) == 5 and recs.rows == [0, 3, 5, 6, 9]
    c = recs.cols
    assert c.node.tolist() == [3, 7, 7, -1, 7]
    assert c.index.tolist() == [-1, 0x2000, 0x2001, 0x1017, 0x2002]
    assert c.ok.tolist() == [False, True, True, True, False]
    assert c.req_row.tolist() == [-1, 2, 4, -1, 8]
    tab = recs.table()
    assert [tab.node_keys[k] for k in tab.node.tolist()] == [3, 7, 7, None, 7]
    assert [tab.result_keys[k] for k in tab.result.tolist()] == [
        "timeout", "ok", "ok", "ok", "abort",
    ]  # fmt: skip
    assert tab.first_seen(tab.result) == [0, 1, 2]
    assert built == []


def test_one_read_builds_one_and_keeps_it() -> None:
    recs, built = _records()
    one = recs.record(2)
    assert built == [[1]] and one["index"] == 0x2001
    assert recs[3] == (6, recs.record(3)) and built == [[1]]  # a tracker record: no build
    everything = list(recs)
    assert everything[2][1] is one  # the full build keeps the dict already handed out
    assert [row for row, _ in everything] == [0, 3, 5, 6, 9]
    assert [r.get("index") for _, r in everything] == [None, 0x2000, 0x2001, 0x1017, 0x2002]


def test_fields_take_and_pickle() -> None:
    recs, built = _records()
    assert recs.fast_part() is not None
    f = recs.fields()  # every transfer by position: the tracker's and the fast ones
    assert [f.record(k).get("index") for k in range(5)] == [None, 0x2000, 0x2001, 0x1017, 0x2002]
    assert f.columns["result"] == ["timeout", "ok", "ok", "ok", "abort"]
    assert f.arrays["t"].tolist()[3] == 0.6 and recs.fields() is f
    kept = recs.take([1, 3], [10, 11])
    assert list(kept) == [(10, recs.record(1)), (11, recs.record(3))]
    back = pickle.loads(pickle.dumps(recs))
    assert type(back) is SdoRecords and list(back) == list(recs) and back == recs


def test_merge_puts_parts_in_row_order_unbuilt() -> None:
    a, built_a = _records()  # rows 0 3 5 6 9
    b = SdoRecords([(1, {"kind": "sdo", "node": 9, "result": "ok"})])
    pos = b.reserve(1)
    part = _part([pos], [4], built_b := [])
    part.cols.ok[:] = True
    b.defer(part)
    # part a's rows 0..9 sit at batch rows 2x; part b's rows 0..4 at 2x+1
    merged, of = SdoRecords.merge([(np.arange(11) * 2, a), (np.arange(6) * 2 + 1, b)])
    assert merged.rows == [0, 3, 6, 9, 10, 12, 18]
    assert of.tolist() == [0, 1, 0, 1, 0, 0, 0]
    assert built_a == [] and built_b == []
    c = merged.cols
    assert c.node.tolist() == [3, 9, 7, 7, 7, -1, 7]
    assert c.req_row.tolist() == [-1, -1, 4, 7, 8, -1, 16]
    assert merged.record(3) == {"kind": "sdo", "node": 7, "index": 0x2000, "result": "abort"}
    assert built_b == [[0]]
    assert [r["node"] for _, r in merged] == [3, 9, 7, 7, 7, None, 7]
    f = merged.fields()  # the parts' columns in the merged order
    assert [f.record(k).get("node") for k in range(7)] == [3, 9, 7, 7, 7, None, 7]
    assert merged.fast_part() is None  # two parts: the roles are read from the notes


def _unique_codes(values: np.ndarray) -> tuple[list, np.ndarray]:
    """The first-seen codes by np.unique, as `_int_codes` always made them."""
    if values.size == 0:
        return [], np.zeros(0, np.int64)
    uniq, first, inv = np.unique(values, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty(order.size, np.int64)
    rank[order] = np.arange(order.size)
    return uniq[order].tolist(), rank[inv.reshape(-1)]


def test_int_codes_small_values_as_unique_gives_them() -> None:
    """Nodes and result codes (-1..0xFFFE) are coded by a count and a radix sort; wider
    values (and other kinds) by np.unique: the same keys and codes either way."""
    from cananalyze.core.sdo_records import SdoTable, _int_codes

    rng = np.random.default_rng(43)
    cases = [
        rng.integers(1, 17, 5000),
        rng.integers(-1, 128, 5000),
        np.zeros(300, np.int64),
        np.full(7, -1, np.int64),
        np.where(rng.random(4000) < 0.01, 1, 0),
        rng.integers(0, 0xFFFF, 3000),  # 0xFFFF itself goes the other way
        np.array([0xFFFF, 3, 0xFFFF, 2], np.int64),
        rng.integers(-5, 3, 500),
        rng.integers(0, 1 << 40, 500),
        rng.integers(0, 256, 900).astype(np.uint8),
        np.array([255, 0, 255], np.uint8),
        np.zeros(0, np.int64),
    ]
    for values in cases:
        keys, codes = _int_codes(values)
        want_keys, want_codes = _unique_codes(values)
        assert keys == want_keys and all(type(k) is int for k in keys)
        assert codes.dtype == np.int64 and np.array_equal(codes, want_codes)
        tab = SdoTable([], codes, [], codes, np.zeros(codes.size), np.arange(codes.size))
        assert tab.first_seen(values) == want_keys
        groups = tab.groups(values)
        assert [g[0] for g in groups] == want_keys
        for key, pos in groups:
            assert np.array_equal(pos, np.flatnonzero(values == key))


def test_first_seen_of_the_tables_own_codes() -> None:
    """The table's node and result codes are numbered as they first come: first_seen of
    them is their numbers in order, as np.unique finds them."""
    recs, _ = _records()
    recs.append(30, {"kind": "sdo", "node": 2, "index": 0x1000, "subindex": 0, "result": "timeout"})
    tab = recs.table()
    for codes, keys in ((tab.node, tab.node_keys), (tab.result, tab.result_keys)):
        want = _unique_codes(codes.copy())[0]
        assert tab.first_seen(codes) == want == list(range(len(keys)))
        assert tab.first_seen(codes.copy()) == want


def test_cols_of_one_fast_part_are_its_columns() -> None:
    """A batch of one fast part in order: its columns as they are (no copy through a sort),
    in a SdoColumns of their own; out of order or beside the tracker's records: sorted."""
    recs = SdoRecords()
    first = recs.reserve(3)
    recs.defer(_part(np.arange(first, first + 3), [4, 6, 9], []))
    cols = recs.cols
    assert cols is not recs._fast[0].cols and cols.row is recs._fast[0].cols.row
    assert cols.row.tolist() == [4, 6, 9] and recs.rows == [4, 6, 9]
    recs.append(12, {"kind": "sdo", "node": 3, "index": 0x1000, "subindex": 0, "result": "ok"})
    assert recs.cols.row.tolist() == [4, 6, 9, 12]
    assert recs.cols.node.tolist() == [7, 7, 7, 3]
