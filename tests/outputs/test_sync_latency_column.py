"""The frames table's sync_latency_ms: each synchronous PDO's time after the SYNC before it,
checked against the same table's own times and services (pyarrow, DuckDB), on a real trace
whose TPDO a network file declares synchronous, and in load()'s frames alike."""

from __future__ import annotations

import duckdb
import numpy as np
import pyarrow.parquet as pq
from conftest import real_file

from cananalyze.api.capture import load
from cananalyze.cli.main import main

LOG = "isPointless__Sevcon/can_230309_150427.txt"  # SYNC every 20 ms, node 3's TPDO1 after it


def _network(tmp_path):
    path = tmp_path / "sevcon.toml"
    path.write_text("[nodes.3.tpdo.1]\ntransmission_type = 1\n")
    return path


def _expected(t: np.ndarray, service: list, can_id: np.ndarray) -> np.ndarray:
    """(t - the latest SYNC's t before it) in ms for 0x183, NaN elsewhere: by hand."""
    out = np.full(len(t), np.nan)
    last = np.nan
    for i, svc in enumerate(service):
        if svc == "sync":
            last = t[i]
        elif can_id[i] == 0x183:
            out[i] = (t[i] - last) * 1000.0
    return out


def test_exported_latency_is_the_time_after_the_sync_before_each_pdo(tmp_path):
    log, out = real_file(LOG), tmp_path / "pq"
    rc = main(
        ["export", str(log), "--network", str(_network(tmp_path)), "--parquet", str(out), "-q"]
    )
    assert rc in (0, 1)
    frames = pq.read_table(out / "frames.parquet")
    assert frames.schema.field("sync_latency_ms").type == "double"
    t = frames["t"].to_numpy()
    got = frames["sync_latency_ms"].to_numpy(zero_copy_only=False)
    want = _expected(t, frames["service"].to_pylist(), frames["can_id"].to_numpy())
    assert np.isnan(want).sum() < len(want) - 250  # the 262 PDOs after their SYNC
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6, equal_nan=True)
    # what check --timing sums up (docs/checks.md: 1.10-1.20 ms), from the table by SQL
    lo, hi, n = duckdb.sql(
        f"select min(sync_latency_ms), max(sync_latency_ms), count(sync_latency_ms) "
        f"from '{out / 'frames.parquet'}'"
    ).fetchall()[0]
    assert (round(lo, 2), round(hi, 2)) == (1.1, 1.2) and n == np.count_nonzero(~np.isnan(want))
    # load()'s frames: the same column
    cap = load(log, network=_network(tmp_path))
    np.testing.assert_allclose(
        cap.frames["sync_latency_ms"].to_numpy(), want, rtol=0, atol=1e-6, equal_nan=True
    )


def test_no_synchronous_pdo_or_no_checks_is_null(tmp_path):
    """Without the network file the TPDO's type is not known (no row is judged), and with
    --no-check nothing is measured: the column is there, every value null."""
    log = real_file(LOG)
    for args, name in (
        ([], "plain"),
        (["--network", str(_network(tmp_path)), "--no-check"], "off"),
    ):
        out = tmp_path / name
        assert main(["export", str(log), *args, "--parquet", str(out), "-q"]) in (0, 1)
        col = pq.read_table(out / "frames.parquet")["sync_latency_ms"]
        assert col.null_count == len(col) > 1000, name
