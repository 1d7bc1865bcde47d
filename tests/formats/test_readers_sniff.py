"""Each real log is claimed by exactly one of these readers' sniffers: its own."""

from __future__ import annotations

import pytest
from conftest import real_file

from cananalyze.formats.registry import FORMATS

MINE = {"asc", "blf", "trc", "canbusanalyzer", "ixxat", "gvret", "pycan_csv", "sevcon", "pycan"}

CASES = [
    ("hardbyte__python-can/logfile.asc", "asc"),
    ("hardbyte__python-can/test_CanFdMessage.asc", "asc"),
    ("hardbyte__python-can/issue_1905.blf", "blf"),
    ("hardbyte__python-can/test_CanMessage_V1_0_BUS1.trc", "trc"),
    ("hardbyte__python-can/test_CanMessage_V2_0_BUS1.trc", "trc"),
    ("hilch__canopen-message-interpreter/pcan3.trc", "trc"),
    ("hilch__canopen-message-interpreter/ixxat1.trc", "ixxat"),
    ("collin80__SavvyCAN/CarBusAnalyzer.trc", "canbusanalyzer"),
    ("collin80__SavvyCAN/GVRET_Log.csv", "gvret"),
    ("isPointless__Sevcon/can_310309_094758.txt", "sevcon"),
    ("collin80__SavvyCAN/candump.log", None),
    ("jclinton830__canopen_test/candump.txt", None),
    ("hilch__canopen-message-interpreter/ixxat1.trc.csv", None),
]


@pytest.mark.parametrize("name,fmt", CASES)
def test_only_its_own_reader_claims_it(name, fmt):
    head = real_file(name).read_bytes()[:65536]
    claimed = [f.name for f in FORMATS if f.name in MINE and f.sniff(head)]
    assert claimed == ([fmt] if fmt else [])


FACADE = [
    ("hardbyte__python-can/test_CanMessage.asc.gz", "asc", 2),
    ("hardbyte__python-can/issue_1905.blf", "blf", 22),
    ("hilch__canopen-message-interpreter/pcan3.trc", "trc", 45422),
    ("hilch__canopen-message-interpreter/ixxat1.trc", "ixxat", 781),
    ("collin80__SavvyCAN/CarBusAnalyzer.trc", "canbusanalyzer", 55),
    ("collin80__SavvyCAN/GVRET_Log.csv", "gvret", 12974),
    ("isPointless__Sevcon/can_230309_150427.txt", "sevcon", 1651),  # its 2 EMCY lines too
]


@pytest.mark.parametrize("name,fmt,count", FACADE)
def test_open_log_picks_the_reader_and_reads_everything(name, fmt, count):
    from cananalyze.formats.source import open_log

    src = open_log(real_file(name), batch_size=10000)
    assert src.fmt.name == fmt
    assert sum(len(b) for b in src.batches()) == count == src.ctx.frames
