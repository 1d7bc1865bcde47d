"""Deterministic N-frame CANopen logs for benchmarks, in candump, ASC and BLF.

A steady-state network of 16 nodes: SYNC every 10 ms, TPDO1-4 and RPDO1-2 per
node, heartbeats every 100 ms, an expedited SDO request/response pair now and
then, and an occasional EMCY. Built as columns (no per-frame Python) so a 10M
frame log takes seconds; candump is written in bulk, ASC/BLF by python-can.

    python benchmarks/generate.py 1000000 benchmarks/out/bench_1m   # .log .asc .blf
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cananalyze.frames import FrameBatch  # noqa: E402
from cananalyze.outputs.logfile import write_log  # noqa: E402

START = 1767225600.0


def generate(n: int, seed: int = 1) -> FrameBatch:
    rng = np.random.default_rng(seed)
    kinds = rng.choice(
        np.array([0x180, 0x280, 0x380, 0x480, 0x200, 0x300, 0x700, 0x080, 0x600, 0x080 + 0x1000]),
        size=n,
        p=[0.22, 0.18, 0.12, 0.08, 0.12, 0.08, 0.06, 0.10, 0.03, 0.01],
    )
    nodes = rng.integers(1, 17, size=n)
    can_id = np.where(kinds == 0x080, 0x080, kinds + nodes).astype(np.uint32)
    emcy = kinds == 0x1080
    can_id[emcy] = (0x080 + nodes[emcy]).astype(np.uint32)
    b = FrameBatch.allocate(n, ("can0",))
    b.t[:] = START + np.cumsum(rng.integers(80, 400, size=n)) / 1e6  # whole microseconds
    b.t[:] = np.round(b.t * 1e6) / 1e6
    b.can_id[:] = can_id
    b.data[:] = rng.integers(0, 256, size=(n, 8), dtype=np.uint8)
    dlc = np.full(n, 8, np.uint8)
    dlc[kinds == 0x700] = 1
    b.data[kinds == 0x700] = 0
    b.data[kinds == 0x700, 0] = 5
    dlc[kinds == 0x080] = 1
    dlc[kinds == 0x380] = 6
    dlc[kinds == 0x300] = 2
    # SDO: expedited upload request; the next frame becomes its response
    sdo = np.flatnonzero(kinds == 0x600)
    sdo = sdo[sdo + 1 < n]
    b.data[sdo] = [0x40, 0x00, 0x18, 0x01, 0, 0, 0, 0]
    resp = sdo + 1
    b.can_id[resp] = (0x580 + nodes[sdo]).astype(np.uint32)
    b.data[resp, :4] = [0x43, 0x00, 0x18, 0x01]
    dlc[resp] = 8
    b.data[emcy, 2] = 0x01
    b.dlc[:] = dlc
    rows = np.arange(8) >= dlc[:, None]
    b.data[rows] = 0
    b.line[:] = np.arange(1, n + 1)
    return b


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    n = int(float(argv[0]))
    stem = Path(argv[1])
    stem.parent.mkdir(parents=True, exist_ok=True)
    suffixes = argv[2].split(",") if len(argv) > 2 else [".log", ".asc", ".blf"]
    batch = generate(n)
    for suffix in suffixes:
        write_log(batch, stem.with_suffix(suffix))
        print(f"wrote {stem.with_suffix(suffix)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
