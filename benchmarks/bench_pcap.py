"""pcap input: cananalyze's columnar reader against the candump reader of the same frames
and against scapy's `rdpcap` (one Python object per packet, what a script would use).

    python benchmarks/bench_pcap.py                 # 1M frames
    python benchmarks/bench_pcap.py --frames 5e4 --repeat 1

Each side reads the file in this process; rounds interleave them. Printed per side:
best wall and CPU (user + system) seconds and frames per second.
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


def _cpu() -> float:
    t = os.times()
    return t.user + t.system


def write_files(n: int, folder: Path) -> tuple[Path, Path]:
    """The same n frames (SocketCAN link type 227, classic CAN) as pcap and candump."""
    rng = np.random.default_rng(0)
    ids = rng.integers(0x80, 0x7FF, n)
    dlc = rng.integers(0, 9, n)
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    data[np.arange(8)[None, :] >= dlc[:, None]] = 0
    rec = np.zeros(n, [("sec", "<u4"), ("usec", "<u4"), ("incl", "<u4"), ("orig", "<u4"),
                       ("id", ">u4"), ("len", "u1"), ("pad", "u1", 3), ("data", "u1", 8)])  # fmt: skip
    rec["sec"] = 1_700_000_000 + np.arange(n) // 1000
    rec["usec"] = (np.arange(n) % 1000) * 1000
    rec["incl"] = rec["orig"] = 16
    rec["id"], rec["len"], rec["data"] = ids, dlc, data
    head = np.array([0xA1B2C3D4], "<u4").tobytes() + bytes([2, 0, 4, 0]) + bytes(8)
    head += np.array([0x40000, 227], "<u4").tobytes()
    pcap = folder / "bench.pcap"
    pcap.write_bytes(head + rec.tobytes())
    from cananalyze.formats.logfile import write_log
    from cananalyze.formats.source import read_all

    log = folder / "bench.log"
    write_log(read_all(pcap), log)
    return pcap, log


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=float, default=1e6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--scapy-frames", type=float, default=1e5, help="scapy reads this many")
    args = ap.parse_args()
    from cananalyze.formats.source import read_all

    n = int(args.frames)
    with tempfile.TemporaryDirectory() as tmp:
        pcap, log = write_files(n, Path(tmp))
        m = min(n, int(args.scapy_frames))
        small = Path(tmp) / "small.pcap"
        small.write_bytes(pcap.read_bytes()[: 24 + 32 * m])
        sides = {"pcap": lambda: len(read_all(pcap)), "candump": lambda: len(read_all(log))}
        try:
            from scapy.utils import rdpcap

            sides["scapy rdpcap"] = lambda: len(rdpcap(str(small)))
        except ImportError:
            pass
        best = {k: (1e9, 1e9, 0) for k in sides}
        for _ in range(args.repeat):
            for name, fn in sides.items():
                w0, c0 = time.perf_counter(), _cpu()
                count = fn()
                w, c = time.perf_counter() - w0, _cpu() - c0
                best[name] = (min(best[name][0], w), min(best[name][1], c), count)
    print(f"read {n:,} frames (scapy: the first {m:,}), best of {args.repeat}:")
    for name, (w, c, count) in best.items():
        print(
            f"  {name:<13} wall {w:8.3f} s  cpu {c:8.3f} s  {count / w:12,.0f} frames/s"
            f"  ({count:,} frames)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
