"""PDOs as a DBC file, written by cantools: `devices KEY --node N --dbc OUT`, `export --dbc`.

Each valid PDO with a known mapping becomes one message at its COB-ID, each mapped
object one Intel (little-endian) signal at its bit offset, as CiA 301 packs them,
with the profile's (or the sidecar's, or the network file's) scaling and unit, the
object's signedness and REAL32/REAL64 as floats. Dummy entries are left as gaps.
Value tables: booleans as false/true, and on a CiA 402 drive the modes of operation
and the controlword's commands (`profiles.cia402.value_tables`). The messages of the
DBC files the log was decoded with (`--dbc-in`) are carried over as they are, and
win over a PDO at the same identifier, as they did when decoding.
cantools builds and formats the file, so any tool that reads DBC reads it.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Iterable
from pathlib import Path

from cananalyze.core.atomic import atomic_write, check_writable
from cananalyze.pipeline.sink import Sink
from cananalyze.protocol.datatypes import DATA_TYPES, DUMMY_INDICES
from cananalyze.protocol.pdo_map import PdoConfig


def _identifier(name: str) -> str:
    """A DBC (C) identifier: letters, digits and underscores, not starting with a digit."""
    name = re.sub(r"[^0-9A-Za-z_]", "_", name) or "signal"
    return name if not name[0].isdigit() else "s_" + name


def _signal(entry, start: int, tables: dict[int, dict[int, str]]):
    from cantools.database.can import Signal
    from cantools.database.conversion import BaseConversion

    dtype = DATA_TYPES.get(entry.datatype)
    kind = dtype.kind if dtype is not None else "uint"
    is_float = kind == "float" and entry.bits in (32, 64)
    scale = 1 if entry.scale is None else entry.scale
    choices = None
    if kind == "bool" and entry.bits == 1:
        choices = {0: "false", 1: "true"}  # the JSONL's booleans, as a value table
    elif entry.subindex == 0 and entry.index in tables:
        limit = 1 << entry.bits
        choices = {v: t for v, t in tables[entry.index].items() if 0 <= v < limit} or None
    return Signal(
        name=_identifier(entry.name),
        start=start,
        length=entry.bits,
        byte_order="little_endian",
        is_signed=kind == "int",
        conversion=BaseConversion.factory(
            scale=scale, offset=entry.offset or 0, choices=choices, is_float=is_float
        ),
        unit=entry.unit or None,
        comment=f"object {entry.index:04X}:{entry.subindex:02X}",
    )


def pdo_message(node: int, pdo: PdoConfig, drive: bool = False):
    """One PDO as a cantools Message, or None when it has nothing to describe; `drive`:
    the node is a CiA 402 drive (its modes and commands get value tables)."""
    from cantools.database.can import Message

    from cananalyze.devices import cia402

    if not pdo.valid or not pdo.mapping or pdo.bits > 64:
        return None
    signals, bit, names = [], 0, set()
    for entry in pdo.mapping:
        if entry.index in DUMMY_INDICES or entry.bits == 0:
            bit += entry.bits
            continue
        sig = _signal(entry, bit, cia402.value_tables() if drive else {})
        base, k = sig.name, 2
        while sig.name in names:  # the same object mapped twice: as decode_pdo names it
            sig.name = f"{base}_{k}"
            k += 1
        names.add(sig.name)
        signals.append(sig)
        bit += entry.bits
    if not signals:
        return None
    kind = "TPDO" if pdo.direction == "tx" else "RPDO"
    owner = f"node{node}"
    return Message(
        frame_id=pdo.cob_id,
        name=f"{owner}_{kind}{pdo.number}",
        length=(bit + 7) // 8,
        signals=signals,
        senders=[owner] if pdo.direction == "tx" else [],
        comment=f"{kind}{pdo.number} of node {node}",
        is_extended_frame=pdo.cob_id > 0x7FF,
    )


def pdo_database(
    pdos: Iterable[tuple[int, PdoConfig]],
    drives: Collection[int] = (),
    carried: Iterable = (),
):
    """A cantools Database of (node, PDO) pairs; a COB-ID given twice keeps the first.
    `drives`: the CiA 402 nodes; `carried`: cantools Messages (a DBC read with the log)
    that go in as they are and replace a PDO at their identifier."""
    import cantools
    from cantools.database.can import Node

    carried = list(carried)
    taken = {(m.frame_id, bool(m.is_extended_frame)) for m in carried}
    messages, nodes = [], set()
    for node, pdo in pdos:
        msg = pdo_message(node, pdo, drive=node in drives)
        if msg is None or (msg.frame_id, msg.is_extended_frame) in taken:
            continue
        taken.add((msg.frame_id, msg.is_extended_frame))
        messages.append(msg)
        nodes.add(node)
    names = {f"node{n}" for n in nodes}
    senders = {s for m in carried for s in m.senders} - names
    return cantools.database.Database(
        messages=sorted(messages + carried, key=lambda m: (m.is_extended_frame, m.frame_id)),
        nodes=[Node(n) for n in sorted(names | senders)],
    )


def write_dbc(path: str | Path, db) -> None:
    """The database as DBC text, written atomically in cp1252: the encoding DBC tools
    (and cantools' `load_file`) expect, so a unit like °C reads back as written."""
    text = db.as_dbc_string().replace("\r\n", "\n")
    for char, spelled in _NOT_CP1252.items():
        text = text.replace(char, spelled)
    with atomic_write(path, "w", encoding="cp1252", newline="\r\n") as f:
        f.write(text.encode("cp1252", "replace").decode("cp1252"))


_NOT_CP1252 = {"\u03a9": "Ohm", "\u2126": "Ohm"}  # units cp1252 cannot hold (omegas)


def bus_path(path: str | Path, bus: str) -> Path:
    """Where a log of several buses puts one bus's DBC: NAME.can1.dbc beside NAME.dbc."""
    p = Path(path)
    return p.with_name(f"{p.stem}.{re.sub(r'[^0-9A-Za-z_.-]', '_', bus)}{p.suffix}")


class DbcSink(Sink):
    """`export --dbc OUT`: the network's PDOs as configured at the end of the log (the
    network model's bindings after the last batch: remaps by SDO included). A log of
    several buses: one DBC per bus, each from its own model (`bus_path`: OUT.can0.dbc,
    OUT.can1.dbc), as node 5's TPDO2 may be mapped differently on each."""

    def __init__(self, path: str | Path) -> None:
        self.path = path
        self.messages = 0
        self.paths: list[Path] = []  # the files written

    def open(self, run) -> None:
        check_writable(self.path)
        self.run = run

    def close(self) -> None:
        decoder = self.run.decoder
        buses = list(decoder.networks())
        if buses == [None]:
            self._write(Path(self.path), decoder)
            return
        for bus in buses:
            self._write(bus_path(self.path, bus), decoder.of_bus(bus))

    def _write(self, path: Path, decoder) -> None:
        """One bus's DBC: its decoder's network model and the DBC it decoded with."""
        model = decoder.network
        bindings = model.bindings if model is not None else {}
        pdos = [
            (b.node, b.config)
            for _, b in sorted(bindings.items())
            if b.problem is None  # a PDO not valid at the end is not on the bus
        ]
        from cananalyze.decode.dbc_processor import DbcDecoder

        drives = {node for node, _ in pdos if model.family(node) == 402}
        carried = [
            m.source
            for p in decoder.processors
            if isinstance(p, DbcDecoder)
            for m in p.dbc.messages.values()
        ]
        db = pdo_database(pdos, drives, carried)
        self.messages += len(db.messages)
        write_dbc(path, db)
        self.paths.append(path)
