"""Live throughput: four saturated 1 Mbit/s buses (>= 32,000 frames/s) through
python-can's virtual bus into LiveSource and the full pipeline `live` runs (SDO
tracker, network model, PDO decoder, EMCY; with --check the Checker too), ~10 s.

Reports frames/s kept, frames dropped (sent minus decoded; should be 0) and the
latency from a frame's send time to the end of its batch's decode.

    python benchmarks/bench_live.py [--rate 32000] [--seconds 10]
        [--network samples/network.toml] [--check samples/rules.yaml]
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import can  # noqa: E402

from cananalyze.checks.build import build_checker  # noqa: E402
from cananalyze.io.live import LiveSource  # noqa: E402
from cananalyze.pipeline import Options, build_decoder  # noqa: E402


def producer(channel: str, rate: float, seconds: float, sent: list[int]) -> None:
    """Send CANopen-like traffic (PDOs, heartbeats, SYNC) at `rate` frames/s in 5 ms bursts."""
    bus = can.Bus(interface="virtual", channel=channel)
    ids = [0x180 + n for n in range(1, 33)] + [0x280 + n for n in range(1, 33)] + [0x080]
    msgs = [can.Message(arbitration_id=i, data=bytes(range(8)), is_extended_id=False) for i in ids]
    # an SDO read of 0x1017 on node 5 and its answer now and then: the tracker's stateful path
    msgs += [
        can.Message(
            arbitration_id=0x605, data=bytes.fromhex("4017100000000000"), is_extended_id=False
        ),
        can.Message(
            arbitration_id=0x585, data=bytes.fromhex("4B17100064000000"), is_extended_id=False
        ),
    ]
    msgs += [
        can.Message(arbitration_id=0x700 + n, data=b"\x05", is_extended_id=False)
        for n in range(1, 5)
    ]
    per_burst = max(1, int(rate * 0.005))
    start = time.perf_counter()
    n = 0
    k = 0
    try:
        while (now := time.perf_counter()) - start < seconds:
            due = int((now - start) * rate)
            while n < due:
                for _ in range(min(per_burst, due - n)):
                    msg = msgs[k % len(msgs)]
                    msg.timestamp = time.time()
                    bus.send(msg)
                    k += 1
                    n += 1
            time.sleep(0.001)
    finally:
        sent[0] = n
        bus.shutdown()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=32_000, help="frames/s to offer (default 32000)")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--network", help="network file for the decoder (PDO decoding of its nodes)")
    ap.add_argument("--check", metavar="RULES", help="also run the Checker with this rules file")
    args = ap.parse_args()

    rx = can.Bus(interface="virtual", channel="bench-live")
    source = LiveSource(rx, channel_name="vcan0")
    checker = build_checker(args.check) if args.check else None
    decoder = build_decoder(Options(network=args.network), checker)
    sent = [0]
    th = threading.Thread(target=producer, args=("bench-live", args.rate, args.seconds, sent))
    lat: list[np.ndarray] = []
    decoded = 0
    signals = 0
    batches = 0

    def stopper():
        th.join()
        time.sleep(0.5)
        source.stop()

    t_start = time.perf_counter()
    th.start()
    threading.Thread(target=stopper, daemon=True).start()
    for fb in source.batches():
        if not len(fb):
            continue
        batch = decoder.decode(fb)
        signals += sum(len(b.rows) for b in batch.signals)
        lat.append(time.time() - fb.t)
        decoded += len(fb)
        batches += 1
    elapsed = time.perf_counter() - t_start
    latency = np.concatenate(lat) * 1e3 if lat else np.zeros(1)
    print(
        f"offered  {sent[0]} frames in {args.seconds:.1f} s = {sent[0] / args.seconds:,.0f} frames/s"
    )
    print(
        f"kept     {decoded} frames = {decoded / args.seconds:,.0f} frames/s "
        f"(wall {elapsed:.1f} s incl. drain), {batches} batches, ring high-water {source.high_water}"
    )
    print(f"dropped  {sent[0] - decoded}")
    print(
        f"latency  send -> decoded: median {np.median(latency):.1f} ms, p99 {np.percentile(latency, 99):.1f} ms, "
        f"max {latency.max():.1f} ms"
    )
    decoder.finish()
    print(f"decoded  {signals} PDO frames into signal values")
    if checker is not None:
        print(f"check    {len(checker.findings)} findings")
    return 0 if sent[0] == decoded else 1


if __name__ == "__main__":
    sys.exit(main())
