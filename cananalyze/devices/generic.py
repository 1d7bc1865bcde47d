"""A device profile from a CiA 4xx table, for a node known only by its device type.

`generic_profile(402)` is a `DeviceProfile` like one read from an EDS: its object
dictionary is built with canopen's own classes (so the network model, the SDO names and
`cananalyze devices` read it the same way), holding the profile's objects and its
default PDOs at the predefined COB-IDs; names and units come as a sidecar. The PDO
mappings are the standard's defaults, not the device's word: `ASSUMED` marks them so that
a frame is decoded as far as it reaches and its length is not judged against a guess.
"""

from __future__ import annotations

from functools import cache

from cananalyze.devices.family import FAMILIES, KEYS
from cananalyze.devices.profile import DeviceProfile, signal_name
from cananalyze.devices.sidecar import Sidecar, SignalSpec

NAMES = {402: "CiA 402 drive (profile defaults)", 401: "CiA 401 generic I/O (profile defaults)"}
U8, U16, U32 = 0x05, 0x06, 0x07


def _var(name: str, index: int, sub: int, datatype: int, raw: str | None):
    from canopen.objectdictionary import ODVariable

    var = ODVariable(name, index, sub)
    var.data_type = datatype
    var.access_type = "rw"
    if raw is not None:
        var.default_raw = raw
        if "$NODEID" not in raw:
            var.default = int(raw, 0)
    return var


def _record(name: str, index: int, subs: list):
    from canopen.objectdictionary import ODRecord

    rec = ODRecord(name, index)
    for var in subs:
        rec.add_member(var)
    return rec


@cache
def generic_profile(profile: int) -> DeviceProfile:
    """The profile for device type `profile` (402, 401), built once."""
    from canopen.objectdictionary import ObjectDictionary

    table = FAMILIES[profile]
    od = ObjectDictionary()
    od.add_object(_var("Device type", 0x1000, 0, U32, f"0x{profile:08X}"))
    by_index: dict[int, list] = {}
    for (index, sub), (name, datatype, _) in table.OBJECTS.items():
        by_index.setdefault(index, []).append(_var(name, index, sub, datatype, None))
    for index, subs in sorted(by_index.items()):
        if len(subs) == 1 and subs[0].subindex == 0:
            od.add_object(subs[0])
        else:
            count = max(v.subindex for v in subs)
            od.add_object(
                _record(subs[0].name, index, [_var("count", index, 0, U8, str(count)), *subs])
            )
    for (direction, number), entries in sorted(table.DEFAULT_PDOS.items()):
        comm = (0x1800 if direction == "tx" else 0x1400) + number - 1
        cob = (0x180 if direction == "tx" else 0x200) + 0x100 * (number - 1)
        od.add_object(
            _record(
                f"{direction.upper()}PDO{number} communication parameter",
                comm,
                [
                    _var("count", comm, 0, U8, "5"),
                    _var("COB-ID", comm, 1, U32, f"$NODEID+0x{cob:X}"),
                ],
            )
        )
        mapping = comm + 0x200
        words = []
        for k, (index, sub) in enumerate(entries, 1):
            bits = {0x02: 8, 0x05: 8, 0x03: 16, 0x06: 16, 0x04: 32, 0x07: 32}[
                table.OBJECTS[(index, sub)][1]
            ]
            words.append(_var(f"entry {k}", mapping, k, U32, f"0x{index:04X}{sub:02X}{bits:02X}"))
        od.add_object(
            _record(
                f"{direction.upper()}PDO{number} mapping parameter",
                mapping,
                [_var("count", mapping, 0, U8, str(len(words))), *words],
            )
        )
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
        od=od,
        sidecar=sidecar,
        generic=True,
    )
