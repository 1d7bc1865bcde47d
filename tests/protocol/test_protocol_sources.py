"""The protocol modules' value tables against sources that are not ours.

python-canopen (its abort texts, SDO, NMT, LSS and TIME constants, read from the
installed package) and the seed manuals' CiA 301 texts (the I-7231D manual's
abort code table, NMT command specifiers, state bytes and error register bits,
read from the seed file). Not compared with a second copy of our own tables.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime

import pytest
from canopen import lss as co_lss
from canopen import nmt as co_nmt
from canopen import timestamp as co_timestamp
from canopen.emcy import EmcyError
from canopen.sdo import constants as co_sdo
from canopen.sdo.exceptions import SdoAbortedError

from cananalyze.protocol import emcy, lss, nmt, sdo
from cananalyze.protocol import time as canopen_time
from tests.conftest import seed_file
from tests.protocol.test_sdo_manual import (
    ABORT_1008_1,
    BLOCK_DOWNLOAD_1400_2,
    BLOCK_UPLOAD_1008,
    SEGMENTED_UPLOAD_1008,
)

I7231D = "002_8af3d3370e33cdbc.txt"


def _words(text: str) -> str:
    """Lower case, punctuation as spaces: 'Sub-index does not exist.' -> 'sub index does not exist'."""
    return " ".join(re.sub(r"[^a-z0-9]+", " ", text.lower()).split())


def _manual() -> str:
    return seed_file(I7231D).read_text(encoding="utf-8")


def _constants(module, prefix: str) -> dict[str, int]:
    return {k[len(prefix) :]: v for k, v in vars(module).items() if k.startswith(prefix)}


# --- SDO -----------------------------------------------------------------------------


def test_abort_codes_are_python_canopens():
    assert set(sdo.ABORT_CODES) == set(SdoAbortedError.CODES)


def _abort_table() -> str:
    """The I-7231D manual's abort code table: what follows each 'XXXX XXXXh' code in it
    (its text is out of order and partly garbled, so codes and texts are not paired)."""
    manual = _manual()
    codes = re.finditer(r"\b0[5-8]0[0-9A] [0-9A-F]{4}h ", manual)
    return " | ".join(_words(manual[m.start() : m.end() + 400]) for m in codes)


def test_abort_texts_read_as_the_manual_or_python_canopen():
    """Each text (its '(block mode only)'-style qualifier aside) is in the I-7231D manual's
    CiA 301 abort table or is python-canopen's text; a code newer than the manual (2005)
    may say more than python-canopen's shorter text."""
    table = _abort_table()
    for code, text in sdo.ABORT_CODES.items():
        ours = _words(re.sub(r"\(.*?\)", "", text))
        theirs = _words(SdoAbortedError.CODES[code])
        if code == 0x06090030:
            # CiA 301 v4.2's "Invalid value for parameter"; the manual and python-canopen's
            # text keep v4.0's "Value range of parameter exceeded", its constant the new name
            assert co_sdo.ABORT_INVALID_VALUE == code and ours == "invalid value for parameter"
        elif ours not in table:
            listed = f"{code >> 16:04x} {code & 0xFFFF:04x}h" in table
            assert ours == theirs or (not listed and ours.startswith(theirs + " ")), hex(code)


def test_block_mode_qualifiers_are_the_manuals():
    manual = _words(_manual())
    for code in (sdo.ABORT_BLOCK_SIZE, sdo.ABORT_SEQUENCE, sdo.ABORT_CRC):
        assert sdo.ABORT_CODES[code].endswith("(block mode only)")
        assert f"{code >> 16:04x} {code & 0xFFFF:04x}h {_words(sdo.ABORT_CODES[code])}" in manual


def test_named_abort_codes_are_python_canopens():
    theirs = _constants(co_sdo, "ABORT_")
    pairs = {
        "TOGGLE": "TOGGLE_NOT_ALTERNATED",
        "TIMEOUT": "TIMED_OUT",
        "COMMAND": "INVALID_COMMAND_SPECIFIER",
        "BLOCK_SIZE": "INVALID_BLOCK_SIZE",
        "SEQUENCE": "INVALID_SEQUENCE_NUMBER",
        "CRC": "CRC_ERROR",
        "WRITE_ONLY": "READ_WRITEONLY",
        "READ_ONLY": "WRITE_READONLY",
        "NO_OBJECT": "NOT_IN_OD",
        "LENGTH": "LENGTH_NOT_MATCHED",
        "TOO_LONG": "LENGTH_TOO_HIGH",
        "TOO_SHORT": "LENGTH_TOO_LOW",
        "NO_SUBINDEX": "NO_SUBINDEX",
        "VALUE_RANGE": "INVALID_VALUE",
    }
    ours = {k: v for k, v in _constants(sdo, "ABORT_").items() if k != "CODES"}
    assert set(ours) == set(pairs)
    assert {k: theirs[pairs[k]] for k in ours} == ours


def test_command_bytes_and_bits_are_python_canopens():
    requests = {
        sdo.CCS_DOWNLOAD_SEGMENT: co_sdo.REQUEST_SEGMENT_DOWNLOAD,
        sdo.CCS_INITIATE_DOWNLOAD: co_sdo.REQUEST_DOWNLOAD,
        sdo.CCS_INITIATE_UPLOAD: co_sdo.REQUEST_UPLOAD,
        sdo.CCS_UPLOAD_SEGMENT: co_sdo.REQUEST_SEGMENT_UPLOAD,
        sdo.CS_ABORT: co_sdo.REQUEST_ABORTED,
        sdo.CCS_BLOCK_UPLOAD: co_sdo.REQUEST_BLOCK_UPLOAD,
        sdo.CCS_BLOCK_DOWNLOAD: co_sdo.REQUEST_BLOCK_DOWNLOAD,
    }
    responses = {
        sdo.SCS_UPLOAD_SEGMENT: co_sdo.RESPONSE_SEGMENT_UPLOAD,
        sdo.SCS_DOWNLOAD_SEGMENT: co_sdo.RESPONSE_SEGMENT_DOWNLOAD,
        sdo.SCS_INITIATE_UPLOAD: co_sdo.RESPONSE_UPLOAD,
        sdo.SCS_INITIATE_DOWNLOAD: co_sdo.RESPONSE_DOWNLOAD,
        sdo.CS_ABORT: co_sdo.RESPONSE_ABORTED,
        sdo.SCS_BLOCK_DOWNLOAD: co_sdo.RESPONSE_BLOCK_DOWNLOAD,
        sdo.SCS_BLOCK_UPLOAD: co_sdo.RESPONSE_BLOCK_UPLOAD,
    }
    for cs, byte in (*requests.items(), *responses.items()):
        assert sdo.command_byte(cs) == byte
    assert sdo.INITIATE_UPLOAD_REQUEST == co_sdo.REQUEST_UPLOAD
    assert sdo.INITIATE_DOWNLOAD_RESPONSE == co_sdo.RESPONSE_DOWNLOAD
    assert sdo.ABORT == co_sdo.REQUEST_ABORTED == co_sdo.RESPONSE_ABORTED
    assert (sdo.EXPEDITED, sdo.SIZE_INDICATED) == (co_sdo.EXPEDITED, co_sdo.SIZE_SPECIFIED)
    assert (sdo.TOGGLE, sdo.LAST_SEGMENT) == (co_sdo.TOGGLE_BIT, co_sdo.NO_MORE_DATA)
    assert (sdo.CRC_SUPPORTED, sdo.BLOCK_SIZE_INDICATED) == (
        co_sdo.CRC_SUPPORTED,
        co_sdo.BLOCK_SIZE_SPECIFIED,
    )
    assert sdo.NO_MORE_SEGMENTS == co_sdo.NO_MORE_BLOCKS
    assert (sdo.BLOCK_INITIATE, sdo.BLOCK_END, sdo.BLOCK_ACK, sdo.BLOCK_START) == (
        co_sdo.INITIATE_BLOCK_TRANSFER,
        co_sdo.END_BLOCK_TRANSFER,
        co_sdo.BLOCK_TRANSFER_RESPONSE,
        co_sdo.START_BLOCK_UPLOAD,
    )


def _head(frames: list[tuple[int, str]], k: int) -> int:
    return int(frames[k][1].split()[0], 16)


def test_command_bytes_compose_the_manuals_frames():
    """The I-7231D manual's worked transfers (test_sdo_manual checks their transcription)."""
    up, block_up, block_down = SEGMENTED_UPLOAD_1008, BLOCK_UPLOAD_1008, BLOCK_DOWNLOAD_1400_2
    c, s = sdo.CCS_UPLOAD_SEGMENT, sdo.SCS_UPLOAD_SEGMENT
    assert _head(up, 0) == sdo.INITIATE_UPLOAD_REQUEST
    assert _head(up, 1) == sdo.initiate_byte(sdo.SCS_INITIATE_UPLOAD, 9)
    assert [_head(up, k) for k in (2, 3, 4, 5)] == [
        sdo.segment_byte(c, 0),
        sdo.segment_byte(s, 0),
        sdo.segment_byte(c, 1),
        sdo.segment_byte(s, 1, unused=5, last=True),
    ]
    bu, su = sdo.CCS_BLOCK_UPLOAD, sdo.SCS_BLOCK_UPLOAD
    assert [_head(block_up, k) for k in range(8)] == [
        sdo.block_byte(bu, sdo.BLOCK_INITIATE),
        sdo.block_byte(su, sdo.BLOCK_INITIATE, sized=True),
        sdo.block_byte(bu, sdo.BLOCK_START),
        1,
        2 | sdo.NO_MORE_SEGMENTS,
        sdo.block_byte(bu, sdo.BLOCK_ACK),
        sdo.block_byte(su, sdo.BLOCK_END, unused=5),
        sdo.block_byte(bu, sdo.BLOCK_END),
    ]
    bd, sd = sdo.CCS_BLOCK_DOWNLOAD, sdo.SCS_BLOCK_DOWNLOAD
    assert [_head(block_down, k) for k in range(6)] == [
        sdo.block_byte(bd, sdo.BLOCK_INITIATE),
        sdo.block_byte(sd, sdo.BLOCK_INITIATE),
        1 | sdo.NO_MORE_SEGMENTS,
        sdo.block_byte(sd, sdo.BLOCK_ACK),
        sdo.block_byte(bd, sdo.BLOCK_END, unused=6),
        sdo.block_byte(sd, sdo.BLOCK_END),
    ]
    assert _head(ABORT_1008_1, 1) == sdo.ABORT


def test_expedited_command_bytes():
    """e, s and n as CiA 301 7.2.4.3.3 lays them out: 0x23/0x27/0x2B/0x2F carry 4..1 bytes."""
    for size, byte in ((4, 0x23), (3, 0x27), (2, 0x2B), (1, 0x2F), (None, 0x22)):
        assert sdo.initiate_byte(sdo.CCS_INITIATE_DOWNLOAD, size, expedited=True) == byte
        assert sdo.expedited_size(byte) == (size or sdo.EXPEDITED_SIZE)
        assert sdo.initiate_byte(sdo.SCS_INITIATE_UPLOAD, size, True) == byte + 0x20


# --- EMCY ----------------------------------------------------------------------------


@pytest.mark.parametrize(("code", "mask", "name"), EmcyError.DESCRIPTIONS)
def test_error_classes_name_python_canopens_classes(code, mask, name):
    """Every class python-canopen names is ours, in the same (or CiA 301's longer) words."""
    assert set(_words(name).split()) - {"or"} <= set(_words(emcy.error_class(code)).split())


def test_register_bits_are_the_manuals():
    """The I-7231D manual lists the 0x1001 bits' meanings in bit order, and its example
    reads register 0x81 as 'manufacturer specific or generic'."""
    text = _words(_manual())
    at = text.index("each bit on the error register is defined as follows")
    rest = text[at:]
    for bit in range(8):
        name = emcy.ERROR_REGISTER_BITS[bit]
        found = rest.find(name)
        assert found >= 0, name
        rest = rest[found + len(name) :]
    assert "81 is the error register it means that the i 7231d has either a " in text
    assert emcy.register_names(0x81) == ["generic", "manufacturer specific"]


# --- NMT -----------------------------------------------------------------------------


def test_nmt_commands_are_the_manuals_and_python_canopens():
    found = re.findall(
        r"([A-Za-z ]{3,40}?) Protocol cs NMT command specifier (\d+)", _manual(), re.S
    )
    named = {int(cs): _words(name) for name, cs in found}
    assert set(named) >= {nmt.START, nmt.STOP, nmt.RESET_NODE, nmt.RESET_COMMUNICATION}
    for cs, words in named.items():
        assert set(_words(nmt.COMMANDS[cs]).split()) <= set(words.split()), (cs, words)
    # and what each does to the node: python-canopen's command -> state table
    assert {cs: co_nmt.COMMAND_TO_STATE[cs] for cs in nmt.COMMANDS} == nmt.COMMAND_STATE
    assert "pre-operational" in nmt.COMMANDS[nmt.ENTER_PRE_OPERATIONAL]


def test_nmt_states_are_the_manuals_and_python_canopens():
    manual = re.search(r"the state of the NMT Slave ((?:\d+ [A-Z ]+?)+) I 7231D", _manual())
    pairs = re.findall(r"(\d+) ([A-Z][A-Z ]*[A-Z])", manual.group(1))
    assert {int(code): _words(name) for code, name in pairs} == {
        code: _words(nmt.STATES[code])
        for code in (nmt.STOPPED, nmt.OPERATIONAL, nmt.PRE_OPERATIONAL)
    }
    assert set(nmt.STATES) <= set(co_nmt.NMT_STATES)
    for code in (nmt.STOPPED, nmt.OPERATIONAL, nmt.PRE_OPERATIONAL):
        assert nmt.STATES[code] == co_nmt.NMT_STATES[code].lower()


def test_state_byte_and_toggle_bit():
    """The guard reply: state in bits 6..0, the toggle in bit 7 (the manual's 'toggle bit')."""
    assert "toggle bit the value of this bit must alternate" in _words(_manual())
    assert nmt.state_name(nmt.PRE_OPERATIONAL | nmt.TOGGLE_BIT) == "pre-operational"
    assert nmt.toggle_of(0x85) == 1 and nmt.toggle_of(0x05) == 0
    assert nmt.STATE_MASK | nmt.TOGGLE_BIT == 0xFF and nmt.STATE_MASK & nmt.TOGGLE_BIT == 0


# --- LSS, TIME -----------------------------------------------------------------------


def test_lss_commands_are_python_canopens():
    theirs = {v: k.lower().replace("_", "") for k, v in _constants(co_lss, "CS_").items()}
    assert set(lss.COMMANDS) == set(theirs)
    for cs, name in lss.COMMANDS.items():
        assert _words(name).replace(" ", "") == theirs[cs], hex(cs)


def test_canopen_epoch_and_time_of_day_are_python_canopens():
    assert canopen_time.CANOPEN_EPOCH.timestamp() == co_timestamp.OFFSET

    class Network:
        def send_message(self, cob_id, data):
            self.data = bytes(data)

    net = Network()
    when = datetime(2026, 1, 1, 12, 30, 15, 250_000, tzinfo=UTC)
    co_timestamp.TimeProducer(net).transmit(when.timestamp())
    assert canopen_time.time_of_day(net.data) == "2026-01-01T12:30:15.250Z"
