"""python-can fallback reader: formats only python-can reads, converted to batches."""

from __future__ import annotations

import can
from conftest import real_file
from readers_util import assert_same_as_python_can, run

from cananalyze.formats.logs import pycan_fallback


def test_asc_through_python_can_equals_python_can():
    path = real_file("hardbyte__python-can/logfile.asc")
    batch, ctx, _ = run(pycan_fallback.read, path, batch_size=6)
    # absolute times (header date + offset), as the fast ASC reader gives them
    expected = list(can.ASCReader(str(path), relative_timestamp=False))
    assert_same_as_python_can(batch, expected, channel_offset=0)
    assert ctx.format == "python-can.asc" and ctx.problems.count == 0


def test_sqlite_log_written_by_python_can(tmp_path):
    path = tmp_path / "log.db"
    msgs = [
        can.Message(
            timestamp=1700000000 + i, arbitration_id=0x180 + i % 5, data=bytes([i % 256] * (i % 9))
        )
        for i in range(300)
    ]
    w = can.SqliteWriter(str(path))
    for m in msgs:
        w.on_message_received(m)
    w.stop()
    head = path.read_bytes()[:64]
    assert pycan_fallback.sniff(head)
    batch, ctx, batches = run(pycan_fallback.read, path, batch_size=128)
    assert [len(b) for b in batches] == [128, 128, 44]
    assert_same_as_python_can(batch, list(can.SqliteReader(str(path))), channel_offset=None)
    assert ctx.absolute_time and ctx.start_time == 1700000000


def test_mdf_is_not_claimed_here():
    """MF4 is formats/logs/mf4.py's (columns through asammdf), not python-can's per Message."""
    assert not pycan_fallback.sniff(b"MDF     4.10    " + bytes(64))


def test_unknown_suffix_is_a_problem():
    batch, ctx, _ = run(pycan_fallback.read, b"whatever", source="x.xyz")
    assert len(batch) == 0 and "unknown log format" in ctx.problems.shown[0].message


def test_suffixes_are_python_cans_other_readers():
    from can.io.player import MESSAGE_READERS

    from cananalyze.formats.logs.pycan_fallback import PYCAN_ONLY_SUFFIXES

    ours = (".asc", ".blf", ".trc", ".csv", ".log", ".mf4")
    assert set(PYCAN_ONLY_SUFFIXES) == {s for s in MESSAGE_READERS if s not in ours}
