"""CiA 401 (generic I/O modules) as tables: the I/O objects and the default PDOs.

Without an EDS the number of channels is not known; the defaults here are CiA 401's
predefined mapping for a module with every default PDO full: 64 digital inputs in
TPDO1, 64 digital outputs in RPDO1, twelve 16-bit analog inputs in TPDO2-4 and twelve
16-bit analog outputs in RPDO2-4. A module with fewer channels sends shorter PDOs, which
the PDO decoder notes as too short: give its EDS (`--eds`) for the real layout.
"""

from __future__ import annotations

U8, I16 = 0x05, 0x03

# (index, subindex) -> (name in the EDS ParameterName style, data type, unit): the signal
# of a mapped object is `profile.signal_name` of it, as for an EDS
OBJECTS: dict[tuple[int, int], tuple[str, int, str | None]] = {}
for _s in range(1, 9):
    OBJECTS[(0x6000, _s)] = (f"Digital inputs {8 * _s - 7}-{8 * _s}", U8, None)
    OBJECTS[(0x6200, _s)] = (f"Digital outputs {8 * _s - 7}-{8 * _s}", U8, None)
for _s in range(1, 13):
    OBJECTS[(0x6401, _s)] = (f"Analog input {_s}", I16, None)
    OBJECTS[(0x6411, _s)] = (f"Analog output {_s}", I16, None)

DEFAULT_PDOS: dict[tuple[str, int], tuple[tuple[int, int], ...]] = {
    ("tx", 1): tuple((0x6000, s) for s in range(1, 9)),
    ("rx", 1): tuple((0x6200, s) for s in range(1, 9)),
}
for _n in range(3):
    DEFAULT_PDOS[("tx", _n + 2)] = tuple((0x6401, 4 * _n + s) for s in range(1, 5))
    DEFAULT_PDOS[("rx", _n + 2)] = tuple((0x6411, 4 * _n + s) for s in range(1, 5))
