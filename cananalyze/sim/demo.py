"""A short, hand-scripted CANopen session: the bundled demo sample.

Three nodes boot, a master reads identity by SDO (expedited and segmented),
configures a heartbeat, gets one abort, starts the network; then SYNC, TIME,
heartbeats, node guarding, PDOs and an emergency raised and cleared. Frame
times are whole microseconds so candump, ASC and BLF carry them identically.

`python -m cananalyze.sim.samples samples/` writes it with the other samples.
"""

from __future__ import annotations

import struct

from cananalyze.core.frames import FLAG_RTR, FLAG_TX, FrameBatch, from_rows
from cananalyze.protocol import nmt
from cananalyze.protocol.sync import FIRST_COUNTER, MAX_COUNTER, next_counter

START = 1767225600.0  # 2026-01-01T00:00:00Z

DAT7014 = 5  # Datexel DAT 7014, 4 analog inputs (TPDO2 = 4 x INTEGER16, 0.1 degC)
MCB560 = 3  # ANDIG MCB-560, digital and analog inputs
GUARDED = 10  # a node supervised by node guarding instead of heartbeat


def _sdo_pairs(node: int, pairs: list[tuple[str, str]]) -> list[tuple[int, bytes, int]]:
    out = []
    for req, resp in pairs:
        out.append((0x600 + node, bytes.fromhex(req), FLAG_TX))
        out.append((0x580 + node, bytes.fromhex(resp), 0))
    return out


def demo_rows() -> list[tuple[float, int, bytes, int]]:
    rows: list[tuple[float, int, bytes, int]] = []
    us = 0

    def at(t_us: int, frames: list[tuple[int, bytes, int]], step_us: int = 700) -> int:
        for k, (cob, data, fl) in enumerate(frames):
            rows.append((START + (t_us + k * step_us) / 1e6, cob, data, fl))
        return t_us + len(frames) * step_us

    us = at(
        0,
        [
            (0x700 + MCB560, bytes([nmt.BOOTUP]), 0),
            (0x700 + DAT7014, bytes([nmt.BOOTUP]), 0),
            (0x700 + GUARDED, bytes([nmt.BOOTUP]), 0),
        ],
        1300,
    )
    name = b"DAT7014\x00"  # 8 bytes: segmented upload in two segments
    us = at(
        20_000,
        _sdo_pairs(
            DAT7014,
            [
                ("4018100100000000", "43181001cd030000"),  # vendor-ID 0x3CD (Datexel)
                ("4018100200000000", "4318100202000000"),  # product code 2 (DAT 7014)
                (
                    "4000100000000000",
                    "4300100091010400",
                ),  # device type 0x00040191 (CiA 401 analog input)
                ("4008100000000000", "4108100008000000"),  # 0x1008 name: segmented, 8 bytes
                ("6000000000000000", "00" + name[:7].hex()),
                ("7000000000000000", "1d" + name[7:].hex() + "000000000000"),
                ("2b17100064000000", "6017100000000000"),  # heartbeat producer 100 ms
            ],
        ),
    )
    us = at(
        us + 5000, _sdo_pairs(MCB560, [("2300200101000000", "8000200100000206")])
    )  # abort 0x06020000
    us = at(us + 5000, _sdo_pairs(MCB560, [("2b17100064000000", "6017100000000000")]))
    at(60_000, [(0x000, bytes([nmt.START, nmt.ALL_NODES]), FLAG_TX)])
    # TIME_OF_DAY: 2026-01-01 00:00:00.100 = 15341 days after 1984-01-01, 100 ms
    at(70_000, [(0x100, struct.pack("<IH", 100, 15341), FLAG_TX)])

    toggle = 0
    counter = FIRST_COUNTER
    for k in range(20):  # two seconds of steady operation
        base = 100_000 + k * 100_000
        at(base, [(0x080, bytes([counter]), FLAG_TX)])
        counter = next_counter(counter, MAX_COUNTER)
        temps = [215 + k, 220 - k, -15 + 2 * k, 1000]
        at(base + 400, [(0x280 + DAT7014, struct.pack("<4h", *temps), 0)])
        at(base + 900, [(0x180 + MCB560, bytes([k & 0xFF, 0x01, 0x00, 0x80]), 0)])
        at(base + 1300, [(0x280 + MCB560, struct.pack("<4h", 2500 + 10 * k, 0, -120, 10000), 0)])
        at(base + 1800, [(0x200 + GUARDED, bytes([k & 0x0F]), FLAG_TX)])
        beat = bytes([nmt.OPERATIONAL])
        at(base + 20_000, [(0x700 + MCB560, beat, 0), (0x700 + DAT7014, beat, 0)], 300)
        if k % 2 == 0:  # node guarding of node 10 every 200 ms
            at(base + 50_000, [(0x700 + GUARDED, b"", FLAG_RTR | FLAG_TX)])
            reply = nmt.OPERATIONAL | (nmt.TOGGLE_BIT if toggle else 0)
            at(base + 50_600, [(0x700 + GUARDED, bytes([reply]), 0)])
            toggle ^= 1
        if k == 9:  # MCB-560 emergency: CAN error warning (Chip-EC 0x40000000)
            at(base + 60_000, [(0x080 + MCB560, bytes.fromhex("0081010000000040"), 0)])
        if k == 15:  # and its reset
            at(base + 60_000, [(0x080 + MCB560, bytes(8), 0)])
    rows.sort(key=lambda r: r[0])
    return rows


def demo_batch() -> FrameBatch:
    return from_rows(demo_rows(), channels=("can0",))
