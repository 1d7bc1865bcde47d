"""Fuzz targets beyond the log readers (harness.run_log): configuration files, EDS/DCF,
XDD/XDC (CiA 311 XML), junk mixed into good frames, and exports that must leave no
temporary file.

Each target returns normally or raises InputError (the project's own input error);
anything else is a crash. Shared by the CI property tests (tests/test_fuzz_targets.py)
and the long campaign (benchmarks/fuzz_campaign.py).
"""

from __future__ import annotations

import os
import random
import re
import tempfile
from pathlib import Path

from cananalyze.core.errors import CananalyzeError, InputError

GOOD_NETWORK = b"""bitrate: 500000
nodes:
  3:
    heartbeat_ms: 100
    tpdo:
      1: {cob_id: 0x183, transmission_type: 255, event_timer: 100}
  5: {heartbeat_ms: 200, guard_time_ms: 0}
sync: {period_us: 100000}
"""
GOOD_TOML = b"""bitrate = 500000
[nodes.3]
heartbeat_ms = 100
[nodes.3.tpdo.1]
cob_id = 0x183
transmission_type = 255
[sync]
period_us = 100000
"""
GOOD_RULES = b"""tolerance: 0.1
rules:
  sdo: {max_latency_ms: 50}
assert:
  - heartbeat: {node: 3, period_ms: 100}
  - pdo_rate: {cob_id: 0x183, min_hz: 5, max_hz: 20}
  - signal: {node: 3, signal: x, min: -1, max: 1}
network:
  nodes:
    3: {heartbeat_ms: 100}
"""
GOOD_EDS = b"""[FileInfo]
FileName=x.eds
FileVersion=1
[DeviceInfo]
VendorName=fuzz
ProductName=fuzz
[MandatoryObjects]
SupportedObjects=2
1=0x1000
2=0x1001
[1000]
ParameterName=Device type
ObjectType=0x7
DataType=0x0007
AccessType=ro
DefaultValue=0x00000191
PDOMapping=0
[1001]
ParameterName=Error register
ObjectType=0x7
DataType=0x0005
AccessType=ro
DefaultValue=0
PDOMapping=1
[1017]
ParameterName=Producer heartbeat time
ObjectType=0x7
DataType=0x0006
AccessType=rw
DefaultValue=100
PDOMapping=0
"""

CANDUMP_LINE = "({t:.6f}) can0 {cob:03X}#{data}"
JUNK = [
    "",
    "   ",
    "garbage",
    "(1.0) can0",
    "(x) can0 181#00",
    "(1.0) can0 181#0",
    "(1.0) can0 G81#00",
    "(1.0) can0 181#001122334455667788",
    "\x00\x00\x00",
    "\xff\xfe",
    "(" * 300,
    "#" * 5000,
    "(1e999) can0 181#00",
    "(nan) can0 181#00",
]


def _tmp(data: bytes, suffix: str) -> str:
    fd, path = tempfile.mkstemp(suffix=suffix)
    with os.fdopen(fd, "wb") as f:
        f.write(data)
    return path


def load_config(data: bytes, kind: str) -> None:
    """`kind`: network.yaml, network.toml or rules.yaml, read by the program's loaders."""
    from cananalyze.checks.rulesfile import load_rules
    from cananalyze.config.netfile import load_network

    path = _tmp(data, "." + kind.split(".")[1])
    try:
        if kind.startswith("rules"):
            load_rules(path)
        else:
            load_network(path)
    except InputError as exc:
        _one_line(exc)
    finally:
        os.unlink(path)


XDD_SEEDS = sorted((Path(__file__).resolve().parents[1] / "data" / "xdd").glob("*.xd[dc]"))
# XML shapes a parser must refuse in one line, not suffer: entity expansion (billion
# laughs), an external entity, nesting beyond the reader's limit, a huge attribute
_LAUGHS = b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY a "aaaaaaaaaa">' + b"".join(
    f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">'.encode() for i in range(9)
)
HOSTILE_XML = [
    _LAUGHS + b']><ISO15745ProfileContainer name="&j;"/>',
    b'<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>'
    b'<ISO15745ProfileContainer name="&e;"/>',
    b"<ISO15745ProfileContainer>"
    + b"<a>" * 100_000
    + b"</a>" * 100_000
    + b"</ISO15745ProfileContainer>",
    b'<ISO15745ProfileContainer><CANopenObjectList><CANopenObject index="1008" name="'
    + b"x" * 2_000_000
    + b'" objectType="7" dataType="0009"/></CANopenObjectList></ISO15745ProfileContainer>',
    b'<?xml version="1.0" encoding="FFFFFFFF"?><ISO15745ProfileContainer/>',
    b"\xef\xbb\xbf<ISO15745ProfileContainer><CANopenObjectList>"
    b'<CANopenObject index="zz" subNumber="-1" objectType="9"/></CANopenObjectList>'
    b"</ISO15745ProfileContainer>",
]


_ATTR = re.compile(rb'([A-Za-z_:][\w:.-]*)="([^"<&]*)"')
_EMPTY_ELEMENT = re.compile(rb"<[A-Za-z][^<>]*/>")
_ODD_VALUES = [
    b"",
    b"0",
    b"-1",
    b"FFFF",
    b"0x",
    b"1e999",
    b"zz",
    b"9" * 60,
    b"&lt;&amp;",
    b"$NODEID+0x180",
    b"7",
    b"9",
    b"0009",
    b"000F",
    b"0x80000000",
    b"true",
]


def mutate_xml(rng: random.Random, data: bytes) -> bytes:
    """Well-formed XML still: attribute values replaced (odd numbers, types, names) and
    empty elements (objects, sub-objects, parameters) dropped or repeated, so that the
    reader's meaning of the document is what gets tested, not the XML parser alone."""
    out = bytearray(data)
    for _ in range(rng.randint(1, 6)):
        if rng.random() < 0.7:
            spots = list(_ATTR.finditer(out))
            if not spots:
                break
            m = rng.choice(spots)
            other = rng.choice(spots).group(2)
            value = rng.choice([*_ODD_VALUES, other, b"%X" % rng.randrange(1 << 32)])
            out[m.start(2) : m.end(2)] = value
        else:
            spots = list(_EMPTY_ELEMENT.finditer(out))
            if not spots:
                break
            m = rng.choice(spots)
            elem = bytes(out[m.start() : m.end()])
            out[m.start() : m.end()] = b"" if rng.random() < 0.5 else elem * rng.randint(2, 40)
    return bytes(out)


def load_xdd(data: bytes, suffix: str = ".xdd") -> None:
    """An XDD/XDC through the reader (read_od: XML by suffix or content) and the device
    profile built from it (PDO mappings, names, units), as --eds reads one."""
    from cananalyze.devices.profile import load_eds as load_profile

    path = _tmp(data, suffix)
    try:
        load_profile(path, 3)
    except InputError as exc:
        _one_line(exc)
    finally:
        os.unlink(path)


def load_eds(data: bytes, suffix: str = ".eds") -> None:
    from cananalyze.devices.eds import read_od

    path = _tmp(data, suffix)
    try:
        read_od(path, 3)
    except InputError as exc:
        _one_line(exc)
    finally:
        os.unlink(path)


def junk_mixed(rng: random.Random, frames: int = 300) -> tuple[bytes, int]:
    """A candump log of `frames` good frames with junk lines between them; (bytes, frames)."""
    lines = []
    for i in range(frames):
        while rng.random() < 0.3:
            lines.append(rng.choice(JUNK))
        data = bytes(rng.randrange(256) for _ in range(rng.randint(0, 8))).hex().upper()
        lines.append(
            CANDUMP_LINE.format(
                t=1.0 + i * 0.001, cob=rng.choice([0x181, 0x703, 0x285, 0x80]), data=data
            )
        )
    return ("\n".join(lines) + "\n").encode("latin-1"), frames


def kept_frames(data: bytes, suffix: str = ".log") -> int:
    """Frames read from a log (lenient)."""
    from cananalyze.formats.source import read_all

    path = _tmp(data, suffix)
    try:
        return len(read_all(path))
    finally:
        os.unlink(path)


def export_leaves_nothing(data: bytes, suffix: str, out: Path) -> list[str]:
    """Export `data` to Parquet, CSV and MCAP in `out`; the names of hidden files left
    (an export that fails must leave none; one that works leaves only its outputs)."""
    from cananalyze.outputs.mcap.sink import McapSink
    from cananalyze.outputs.tables.stream import TableSink
    from cananalyze.pipeline import Options, build_decoder, open_source, run

    path = _tmp(data, suffix)
    try:
        opts = Options(checks=True)
        sinks = [
            TableSink(out / "pq", "parquet"),
            TableSink(out / "csv", "csv"),
            McapSink(out / "x.mcap"),
        ]
        try:
            run(open_source(path, opts), build_decoder(opts), sinks, opts)
        except CananalyzeError:
            pass
    finally:
        os.unlink(path)
    return sorted(str(p.relative_to(out)) for p in out.rglob(".*"))


def _one_line(exc: InputError) -> None:
    msg = str(exc)
    assert msg and "\n" not in msg, f"InputError message is not one line: {msg!r}"
