"""DBC decoding: cananalyze's columns against cantools' `decode_message` per frame.

    python benchmarks/bench_dbc.py              # 1M frames of the Axiomatic DBC's 3 messages
    python benchmarks/bench_dbc.py --frames 5e4 --repeat 1

Both decode the same frames (in memory) with the same DBC; rounds interleave the two so
the machine's load weighs on both alike. Printed per side: best wall and CPU (user +
system) seconds and frames per second, then the ratio. The values are compared too: a
fast path that gave other numbers would not count.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

# the DBC of the real Axiomatic log (../shared), written out so the script runs anywhere
DBC = """VERSION ""

NS_ :

BS_:

BU_:

BO_ 511 Com001_TPDO1: 8 Vector__XXX
 SG_ input1_value : 0|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input2_value : 16|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input3_value : 32|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input4_value : 48|16@1- (0.001,0) [0|65535] "" Vector__XXX

BO_ 767 Com001_TPDO2: 8 Vector__XXX
 SG_ input5_value : 0|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input6_value : 16|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input7_value : 32|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input8_value : 48|16@1- (0.001,0) [0|65535] "" Vector__XXX

BO_ 1023 Com001_TPDO3: 8 Vector__XXX
 SG_ input9_value : 0|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input10_value : 16|16@1- (0.001,0) [0|65535] "" Vector__XXX
 SG_ input11_freq : 32|16@1+ (0.1,0) [0|65535] "Hz" Vector__XXX
 SG_ input12_value : 48|16@1- (0.001,0) [0|65535] "" Vector__XXX
"""


def _cpu() -> float:
    t = os.times()
    return t.user + t.system


def _frames(n: int):
    from cananalyze.core.frames import FrameBatch

    rng = np.random.default_rng(0)
    fb = FrameBatch.allocate(n, ("can0",))
    fb.t[:] = np.arange(n) * 1e-4
    fb.can_id[:] = np.array([0x1FF, 0x2FF, 0x3FF], np.uint32)[np.arange(n) % 3]
    fb.dlc[:] = 8
    fb.data[:] = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    return fb


def ours(fb, path: str):
    """The decoder `--dbc` builds, on the whole batch (classifier, model, PDO and DBC)."""
    from cananalyze.pipeline import Options, build_decoder

    return build_decoder(Options(dbc=(path,))).decode(fb)


def theirs(fb, db) -> list[dict]:
    by_id = {m.frame_id: m for m in db.messages}
    data = fb.data.tobytes()
    ids = fb.can_id.tolist()
    return [by_id[i].decode(data[8 * k : 8 * k + 8]) for k, i in enumerate(ids)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=float, default=1e6)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    import cantools

    n = int(args.frames)
    fb = _frames(n)
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "axiomatic.dbc")
        Path(path).write_text(DBC)
        db = cantools.database.load_file(path)
        best = {"cananalyze": (1e9, 1e9), "cantools": (1e9, 1e9)}
        for _ in range(args.repeat):
            for name in best:
                w0, c0 = time.perf_counter(), _cpu()
                out = ours(fb, path) if name == "cananalyze" else theirs(fb, db)
                w, c = time.perf_counter() - w0, _cpu() - c0
                best[name] = (min(best[name][0], w), min(best[name][1], c))
                if name == "cananalyze":
                    mine = out
                else:
                    ref = out
    # same values: every signal of every frame
    for sb in mine.signals:
        for sig, col in sb.columns.items():
            want = np.array([ref[r][sig] for r in sb.rows.tolist()])
            assert np.allclose(col, want), sig
    print(f"DBC decode of {n:,} frames (3 messages, 12 signals), best of {args.repeat}:")
    for name, (w, c) in best.items():
        print(f"  {name:<11} wall {w:8.3f} s  cpu {c:8.3f} s  {n / w:12,.0f} frames/s")
    (wo, co), (wt, ct) = best["cananalyze"], best["cantools"]
    print(f"  cantools / cananalyze: wall {wt / wo:.1f}x  cpu {ct / co:.1f}x  (values equal)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
