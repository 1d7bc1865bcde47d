"""Deterministic N-frame CANopen logs for benchmarks, in candump, ASC and BLF.

A steady-state network of 16 healthy nodes: SYNC with its counter, TPDO1-4 and
RPDO1-2 per node, each node's heartbeat every 256 frames (about 61 ms), an
expedited SDO request/response pair now and then, and an occasional EMCY saying
"no error" (`check` finds nothing on it; `--faults`: a bus that breaks a rule every
few frames, for the checks' cost). Built as columns (no per-frame Python) so a 10M
frame log takes seconds; candump and ASC are written in bulk (ASC byte for byte
what python-can's ASCWriter writes, which takes ~14 s per 1M frames), BLF by
python-can (~8 s per 1M frames).

    python benchmarks/generate.py 1000000 benchmarks/out/bench_1m   # .log .asc .blf
    python benchmarks/generate.py 1000000 benchmarks/out/faulty_1m .log --faults  # for check
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cananalyze.core.columns.bytecols import digits as _digits  # noqa: E402  (the text writer's ASCII digits)
from cananalyze.core.frames import FLAG_ERR, FLAG_EXT, FLAG_FD, FLAG_RTR, FLAG_TX, FrameBatch  # noqa: E402
from cananalyze.formats.logfile import write_log  # noqa: E402

START = 1767225600.0
# The traffic's version, in the logs' names (`log_stem`): a change of what is generated
# must not be measured on logs an older generator left in the output folder.
# 2: a healthy bus (version 1 drew every frame's kind at random, so its heartbeats came
# at random times, its SYNC counters were random, its EMCYs were never reset and 3 % of
# its SDO responses were overwritten: 424k true findings per 10M frames).
# 3: no error EMCY on the healthy bus (version 2 raised one and reset it, but every error
# raised is a finding: 47k per 10M frames, and `check` exited 1), its EMCYs are "no error".
VERSION = 3


def log_stem(out: Path, n: int, faults: bool = False) -> Path:
    """Where the benchmarks keep the n-frame logs (suffix added per format); `faults`:
    those of the faulty bus."""
    return out / f"{'faulty' if faults else 'bench'}_v{VERSION}_{n}"


def generate(n: int, seed: int = 1, faults: bool = False) -> FrameBatch:
    """n frames of the healthy bus (`check` exits 0 on it); `faults`: version 1's traffic instead (kinds drawn at
    random: heartbeats at random times, random SYNC counters, EMCYs never reset, SDO
    responses overwritten), a bus that breaks a rule every few frames."""
    rng = np.random.default_rng(seed)
    kinds = rng.choice(
        np.array([0x180, 0x280, 0x380, 0x480, 0x200, 0x300, 0x700, 0x080, 0x600, 0x080 + 0x1000]),
        size=n,
        p=[0.22, 0.18, 0.12, 0.08, 0.12, 0.08, 0.06, 0.10, 0.03, 0.01],
    )
    nodes = rng.integers(1, 17, size=n)
    if not faults:
        # heartbeats on a schedule: every 16th frame, the nodes in turn, so each node beats
        # every 256 frames (about 61 ms, within a few per cent); elsewhere a TPDO1 instead
        kinds[kinds == 0x700] = 0x180
        kinds[::16] = 0x700
        nodes[::16] = np.arange(0, n, 16) // 16 % 16 + 1
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
    if not faults:
        sync = np.flatnonzero(kinds == 0x080)
        b.data[sync, 0] = np.arange(sync.size) % 240 + 1  # CiA 301: counts 1..240, wraps
        # EMCYs say "no error" (code 0, register 0: what a node sends once its errors are
        # reset): a raised error is a finding of its own, and the healthy bus has none
        b.data[emcy] = 0
    dlc[kinds == 0x380] = 6
    dlc[kinds == 0x300] = 2
    # SDO: expedited upload request of a process value (0x6000:01, read input 8-bit: random
    # data is a plausible answer; a communication object's read-back would configure the
    # network model); the next frame becomes its response
    sdo = np.flatnonzero(kinds == 0x600)
    if faults:
        sdo = sdo[sdo + 1 < n]
    else:
        # the response takes the place of a PDO (not of a heartbeat, SYNC or EMCY: a
        # healthy bus); a request with no such place is a TPDO1 instead
        pdos = (0x180, 0x280, 0x380, 0x480, 0x200, 0x300)
        ok = np.isin(kinds[np.minimum(sdo + 1, n - 1)], pdos) & (sdo + 1 < n)
        b.can_id[sdo[~ok]] = (0x180 + nodes[sdo[~ok]]).astype(np.uint32)
        sdo = sdo[ok]
    b.data[sdo] = [0x40, 0x00, 0x60, 0x01, 0, 0, 0, 0]
    resp = sdo + 1
    b.can_id[resp] = (0x580 + nodes[sdo]).astype(np.uint32)
    b.data[resp, :4] = [0x43, 0x00, 0x60, 0x01]
    dlc[resp] = 8
    if faults:
        b.data[emcy, 2] = 0x01  # after the SDO responses: it overwrites some of them
    b.dlc[:] = dlc
    rows = np.arange(8) >= dlc[:, None]
    b.data[rows] = 0
    b.line[:] = np.arange(1, n + 1)
    return b


_HEX = np.frombuffer(b"0123456789ABCDEF", np.uint8)


def write_asc(batch: FrameBatch, path: Path) -> bool:
    """ASC as python-can's ASCWriter writes it, built as one byte matrix.

    Only for what the generator makes (one channel, classic standard data
    frames, non-decreasing times); returns False for anything else.
    """
    from datetime import datetime

    import can

    n = len(batch)
    odd = FLAG_EXT | FLAG_RTR | FLAG_ERR | FLAG_FD | FLAG_TX
    if n == 0 or len(batch.channels) > 1 or (batch.flags & odd).any() or (batch.dlc > 8).any():
        return False
    if (np.diff(batch.t) < 0).any():
        return False
    start = float(batch.t[0])
    rel = batch.t - start  # the float python-can formats with " 9.6f"
    us = np.rint(rel * 1e6).astype(np.int64)
    if np.abs(rel * 1e6 - us).max() > 0.49:
        return False  # near a half microsecond: Python's rounding might differ
    sec, frac = np.divmod(us, 1_000_000)
    w = max(1, len(str(int(sec.max()))))
    ip = _digits(sec, w)
    sec_len = np.ones(n, np.int64)
    for d in range(1, w):
        sec_len += sec >= 10**d
    ip[np.arange(w)[None, :] < (w - sec_len)[:, None]] = 0  # no leading zeros
    ident = np.empty((n, 3), np.uint8)
    for j in range(3):
        ident[:, j] = _HEX[(batch.can_id >> (4 * (2 - j))) & 0xF]
    ident[:, 0] = np.where(batch.can_id >= 0x100, ident[:, 0], 0)
    ident[:, 1] = np.where(batch.can_id >= 0x10, ident[:, 1], 0)
    idpad = np.full((n, 12), 32, np.uint8)  # "{id:<15}": spaces after the id
    short = 3 - ((batch.can_id >= 0x100).astype(np.int64) + (batch.can_id >= 0x10) + 1)
    extra = np.zeros((n, 2), np.uint8)  # the spaces a shorter id leaves
    extra[:, 0] = np.where(short >= 1, 32, 0)
    extra[:, 1] = np.where(short >= 2, 32, 0)
    data = np.full((n, 8, 3), 32, np.uint8)
    data[:, :, 1] = _HEX[batch.data >> 4]
    data[:, :, 2] = _HEX[batch.data & 0xF]
    data[np.arange(8)[None, :] >= batch.dlc[:, None].astype(np.int64)] = 0
    parts = [
        np.full((n, 1), 32, np.uint8),
        ip,
        np.full((n, 1), ord("."), np.uint8),
        _digits(frac, 6),
        np.frombuffer(b" 1  ", np.uint8)[None, :].repeat(n, 0),
        ident,
        extra,
        idpad,
        np.frombuffer(b" Rx   d ", np.uint8)[None, :].repeat(n, 0),
        (48 + batch.dlc).astype(np.uint8)[:, None],
        np.full((n, 1), 32, np.uint8),
        data.reshape(n, 24)[:, 1:],
        np.full((n, 1), ord("\n"), np.uint8),
    ]
    mat = np.concatenate(parts, axis=1)
    body = mat[mat != 0].tobytes()
    stamp = can.ASCWriter._format_header_datetime(can.ASCWriter, datetime.fromtimestamp(start))  # type: ignore[arg-type]
    head = (
        f"date {stamp}\nbase hex  timestamps absolute\ninternal events logged\n"
        f"Begin Triggerblock {stamp}\n 0.000000 Start of measurement\n"
    ).encode()
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        f.write(head)
        f.write(body)
        f.write(b"End TriggerBlock\n")
    tmp.replace(path)
    return True


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__)
        return 2
    faults = "--faults" in argv  # version 1's faulty bus (the tests' rules workload)
    argv = [a for a in argv if a != "--faults"]
    n = int(float(argv[0]))
    stem = Path(argv[1])
    stem.parent.mkdir(parents=True, exist_ok=True)
    suffixes = argv[2].split(",") if len(argv) > 2 else [".log", ".asc", ".blf"]
    batch = generate(n, faults=faults)
    for suffix in suffixes:
        if suffix == ".asc" and write_asc(batch, stem.with_suffix(suffix)):
            print(f"wrote {stem.with_suffix(suffix)}")
            continue
        write_log(batch, stem.with_suffix(suffix))
        print(f"wrote {stem.with_suffix(suffix)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
