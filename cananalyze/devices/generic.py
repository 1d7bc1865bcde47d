"""A device profile from a CiA 4xx table, for a node known only by its device type.

`generic_profile(402)` is a `DeviceProfile` like one read from an EDS: its object
dictionary is built with canopen's own classes (so the network model, the SDO names and
`cananalyze devices` read it the same way), holding the profile's objects and its
default PDOs at the predefined COB-IDs; names and units come as a sidecar. The PDO
mappings are the standard's defaults, not the device's word: `ASSUMED` marks them so that
a frame is decoded as far as it reaches and its length is not judged against a guess.
"""

from __future__ import annotations

from functools import cache, partial

from cananalyze.devices.family import FAMILIES, KEYS
from cananalyze.devices.od_facts import OdFacts, Var
from cananalyze.devices.profile import DeviceProfile, signal_name
from cananalyze.devices.sidecar import Sidecar, SignalSpec

NAMES = {402: "CiA 402 drive (profile defaults)", 401: "CiA 401 generic I/O (profile defaults)"}
U8, U16, U32 = 0x05, 0x06, 0x07


def _var(name: str, index: int, sub: int, datatype: int, raw: str | None) -> tuple:
    """(sub-index, Var) as canopen reads such an entry from an EDS (DefaultValue=raw)."""
    default = int(raw, 0) if raw is not None and "$NODEID" not in raw else None
    return sub, Var(name, datatype, False, None, raw, None, default)


def _objects(profile: int) -> dict[int, tuple[str, str, dict]]:
    """{index: (kind, name, {sub: Var})}: the profile's objects and its default PDOs, the
    one source of both its facts and its canopen dictionary."""
    table = FAMILIES[profile]
    out = {
        0x1000: (
            "var",
            "Device type",
            dict([_var("Device type", 0x1000, 0, U32, f"0x{profile:08X}")]),
        )
    }
    by_index: dict[int, list] = {}
    for (index, sub), (name, datatype, _) in table.OBJECTS.items():
        by_index.setdefault(index, []).append(_var(name, index, sub, datatype, None))
    for index, subs in sorted(by_index.items()):
        if len(subs) == 1 and subs[0][0] == 0:
            out[index] = ("var", subs[0][1].name, dict(subs))
        else:
            count = max(sub for sub, _ in subs)
            members = [_var("count", index, 0, U8, str(count)), *subs]
            out[index] = ("record", subs[0][1].name, dict(members))
    for (direction, number), entries in sorted(table.DEFAULT_PDOS.items()):
        comm = (0x1800 if direction == "tx" else 0x1400) + number - 1
        cob = (0x180 if direction == "tx" else 0x200) + 0x100 * (number - 1)
        members = [
            _var("count", comm, 0, U8, "5"),
            _var("COB-ID", comm, 1, U32, f"$NODEID+0x{cob:X}"),
        ]
        out[comm] = (
            "record",
            f"{direction.upper()}PDO{number} communication parameter",
            dict(members),
        )
        mapping = comm + 0x200
        words = []
        for k, (index, sub) in enumerate(entries, 1):
            bits = {0x02: 8, 0x05: 8, 0x03: 16, 0x06: 16, 0x04: 32, 0x07: 32}[
                table.OBJECTS[(index, sub)][1]
            ]
            words.append(_var(f"entry {k}", mapping, k, U32, f"0x{index:04X}{sub:02X}{bits:02X}"))
        members = [_var("count", mapping, 0, U8, str(len(words))), *words]
        out[mapping] = (
            "record",
            f"{direction.upper()}PDO{number} mapping parameter",
            dict(members),
        )
    return out


def _dictionary(profile: int):
    """The objects as canopen's ObjectDictionary (the simulator and DCF output read it)."""
    from canopen.objectdictionary import ObjectDictionary, ODRecord, ODVariable

    def variable(index: int, sub: int, v: Var):
        var = ODVariable(v.name, index, sub)
        var.data_type = v.data_type
        var.access_type = "rw"
        if v.default_raw is not None:
            var.default_raw = v.default_raw
            if v.default is not None:
                var.default = v.default
        return var

    od = ObjectDictionary()
    for index, (kind, name, subs) in _objects(profile).items():
        if kind == "var":
            od.add_object(variable(index, 0, subs[0]))
        else:
            rec = ODRecord(name, index)
            for sub, v in subs.items():
                rec.add_member(variable(index, sub, v))
            od.add_object(rec)
    return od


@cache
def generic_profile(profile: int) -> DeviceProfile:
    """The profile for device type `profile` (402, 401), built once; canopen's dictionary
    of it only when something asks for the whole dictionary."""
    table = FAMILIES[profile]
    objects = {index: (kind, subs) for index, (kind, _, subs) in _objects(profile).items()}
    info = {"vendor_number": None, "product_number": None, "product_name": None}
    key = next(k for k, v in KEYS.items() if v == profile)
    sidecar = Sidecar(
        key=key,
        name=NAMES[profile],
        signals={
            obj: SignalSpec(signal_name(name), unit)
            for obj, (name, _, unit) in table.OBJECTS.items()
        },
    )
    return DeviceProfile(
        key=key,
        name=NAMES[profile],
        vendor_id=None,
        product_code=None,
        device_type=profile,
        device_name=None,
        notes=[
            f"CiA {profile} defaults, used when the device type names the profile and no EDS "
            "is given; PDO mappings are the standard's defaults until the log shows the real ones"
        ],
        source=f"CiA {profile} tables (cananalyze/devices/cia{profile}.py)",
        facts=OdFacts(objects, info, None),
        load_od=partial(_dictionary, profile),
        sidecar=sidecar,
        generic=True,
    )
