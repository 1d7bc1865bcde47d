"""signals.parquet: one row per PDO frame, a column per signal, read with pyarrow and DuckDB.

A remap mid-log (SDO writes to 0x1A01, the I-7231D's manual procedure) brings new
signals after the first row groups were written: the file is still one file, the
earlier rows null in the new columns; a unit written mid-log (DAT 7014 sensor type)
gives the signal a second column. Its long view (DuckDB's UNPIVOT) is load()'s
`signals` in every case, and the pure path writes the same file.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import duckdb
import pyarrow.parquet as pq
import pytest
from conftest import ROOT, SAMPLES
from exported import NETWORK, TABLES, assert_wide_signals_is, export, wide_signals_as_long

import cananalyze
from cananalyze.devices.builtin import load_builtin
from cananalyze.formats.logfile import write_log
from cananalyze.outputs.tables import writer as table_writer
from tests.decode.test_network_model import frames_at, sdo_write

I7231D = {1: "i7231d"}


def _remap_log(path: Path) -> Path:
    """30 TPDO1 frames, then TPDO2 remapped to AI channels 2 and 3 and sent 30 times."""
    seq = [(0x181, bytes([i, 1, 2])) for i in range(30)]
    seq += sdo_write(1, 0x1801, 1, 0x80000281)  # disable
    seq += sdo_write(1, 0x1A01, 0, 0, 1)
    seq += sdo_write(1, 0x1A01, 1, 0x64010210) + sdo_write(1, 0x1A01, 2, 0x64010310)
    seq += sdo_write(1, 0x1A01, 0, 2, 1) + sdo_write(1, 0x1801, 1, 0x281)  # enable
    seq += [
        (0x281, (i * 10).to_bytes(2, "little") + (i * 20).to_bytes(2, "little")) for i in range(30)
    ]
    write_log(frames_at(seq), path)
    return path


@pytest.mark.parametrize("row_group", [8, 1 << 18])
def test_remap_mid_log_new_columns_in_one_file(tmp_path, monkeypatch, row_group):
    """Row groups of 8 rows: the file was opened with TPDO1's columns only; the remap's
    signals end that part and the parts are merged. Either way one file, same content."""
    monkeypatch.setattr(table_writer, "ROW_GROUP", row_group)
    log = _remap_log(tmp_path / "remap.log")
    out = export(log, tmp_path / "x", size=10, device=I7231D)["parquet"]  # batches of 10
    path = out / "signals.parquet"
    assert sorted(p.name for p in out.iterdir()) == sorted(
        f"{n}.parquet" for n in TABLES
    )  # no part files left behind
    f = pq.ParquetFile(path)
    if row_group == 8:
        assert f.num_row_groups > 2
    table = f.read()
    cap = cananalyze.load(log, device=I7231D)
    names = list(cap.signals["signal"].unique())
    assert table.column_names == ["t", "node", "pdo", "cob_id", *names]
    new = [n for n in names if n.startswith("ai")]
    assert len(new) == 2
    rows = table.to_pydict()
    assert rows["pdo"] == ["tpdo1"] * 30 + ["tpdo2"] * 30  # one row per PDO frame
    for n in new:  # null before the remap, the frames' values after
        assert rows[n][:30] == [None] * 30
        assert all(v is not None for v in rows[n][30:])
    assert rows["di_byte1"][:30] == [float(i) for i in range(30)]
    assert rows["di_byte1"][30:] == [None] * 30
    assert_wide_signals_is(cap, path)


def test_duckdb_queries_the_wide_table(tmp_path):
    """The README's query: per node and PDO, frames and a signal's mean, straight from
    the file (a column per signal: no pivot in SQL)."""
    log = _remap_log(tmp_path / "remap.log")
    out = export(log, tmp_path / "x", device=I7231D)["parquet"]
    cap = cananalyze.load(log, device=I7231D)
    ai = sorted(n for n in cap.signals["signal"].unique() if n.startswith("ai"))
    got = duckdb.sql(
        f"""SELECT pdo, count(*) AS frames, avg("{ai[0]}") AS mean, count("{ai[0]}") AS n
        FROM '{out}/signals.parquet' GROUP BY pdo ORDER BY pdo"""
    ).fetchall()
    s = cap.signals
    want = s[s["signal"] == ai[0]]["value"]
    assert got == [("tpdo1", 30, None, 0), ("tpdo2", 30, pytest.approx(want.mean()), 30)]
    # a time window: statistics on t are written (and only there)
    meta = pq.ParquetFile(out / "signals.parquet").metadata.row_group(0)
    stats = {meta.column(i).path_in_schema: meta.column(i).is_stats_set for i in range(4)}
    assert stats == {"t": True, "node": False, "pdo": False, "cob_id": False}
    ((n,),) = duckdb.sql(
        f"SELECT count(*) FROM '{out}/signals.parquet' WHERE t BETWEEN 0.0 AND 0.0095"
    ).fetchall()
    assert n == 10


def test_same_signal_in_another_unit_is_another_column(tmp_path):
    """Two DAT 7014s, node 6's input 1 set to ohms (sensor type 0x10 by SDO) before its
    first PDO: `ch1` of node 5 is in °C, of node 6 in Ω, so node 6's values go to a
    column `ch1 [Ω]`, the unit in each column's field metadata."""
    prof = load_builtin("dat7014")

    def cob(node: int) -> int:
        return next(
            p.cob_id for p in prof.pdos(node) if p.direction == "tx" and p.valid and p.mapping
        )

    pdo = bytes.fromhex("E8030000") + bytes(4)  # ch1 = 1000
    seq = sdo_write(6, 0x2107, 1, 0x10, 1) + [(cob(5), pdo), (cob(6), pdo)] * 2
    log = tmp_path / "units.log"
    write_log(frames_at(seq), log)
    devices = {5: "dat7014", 6: "dat7014"}
    out = export(log, tmp_path / "x", device=devices)["parquet"]
    schema = pq.read_schema(out / "signals.parquet")
    assert schema.field("ch1").metadata == {b"signal": b"ch1", b"unit": "°C".encode()}
    assert schema.field("ch1 [Ω]").metadata == {b"signal": b"ch1", b"unit": "Ω".encode()}
    table = pq.read_table(out / "signals.parquet").to_pydict()
    assert table["node"] == [5, 6, 5, 6]
    assert table["ch1 [Ω]"] == [None, 1000.0, None, 1000.0]
    assert table["ch1"] == [100.0, None, 100.0, None]  # 0.1 °C per count
    assert_wide_signals_is(cananalyze.load(log, device=devices), out / "signals.parquet")


def test_signal_named_like_a_key_column(tmp_path):
    """A DBC signal called `node` cannot be the key column: it is written `signal:node`."""
    dbc = tmp_path / "k.dbc"
    dbc.write_text(
        'VERSION ""\n\nBS_:\n\nBU_: ECU\n\nBO_ 266 M: 2 ECU\n'
        ' SG_ node : 0|8@1+ (1,0) [0|255] "" Vector__XXX\n'
        ' SG_ t : 8|8@1+ (1,0) [0|255] "" Vector__XXX\n'
    )
    log = tmp_path / "k.log"
    log.write_text("".join(f"({i}.0) can0 10A#{i:02X}{2 * i:02X}\n" for i in range(4)))
    out = tmp_path / "pq"
    cmd = [sys.executable, "-m", "cananalyze", "export", str(log), "--dbc-in", str(dbc)]
    subprocess.run([*cmd, "--parquet", str(out), "-q"], check=True, cwd=ROOT)
    table = pq.read_table(out / "signals.parquet")
    assert table.column_names == ["t", "node", "pdo", "cob_id", "signal:node", "signal:t"]
    assert table.column("signal:node").to_pylist() == [0.0, 1.0, 2.0, 3.0]
    long = wide_signals_as_long(out / "signals.parquet")
    assert sorted(set(long["signal"])) == ["node", "t"]


def test_pure_path_writes_the_same_wide_file(tmp_path):
    """CANANALYZE_PURE=1 (no compiled helper): the same signals and frames files."""
    log = SAMPLES / "faults.log"
    tables = {}
    for mode in ("fast", "pure"):
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        env.pop("CANANALYZE_PURE", None)
        if mode == "pure":
            env["CANANALYZE_PURE"] = "1"
        out = tmp_path / mode
        cmd = [sys.executable, "-m", "cananalyze", "export", str(log), "--network", NETWORK]
        subprocess.run([*cmd, "--parquet", str(out), "-q"], check=True, env=env, cwd=ROOT)
        tables[mode] = {n: pq.read_table(out / f"{n}.parquet") for n in ("signals", "frames")}
    for name in ("signals", "frames"):
        assert tables["fast"][name].equals(tables["pure"][name], check_metadata=True), name
    assert tables["fast"]["signals"].num_rows > 0
